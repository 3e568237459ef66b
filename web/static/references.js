// References (coach): upload a BVH through the page, preview its postures, edit the domain
// file (segment names, per-bone weights and tolerances).
"use strict";
(function () {
  const listEl = document.getElementById("ref-list");
  const BONES = JSON.parse(listEl.dataset.bones);
  const form = document.getElementById("ref-upload");
  const err = document.getElementById("ref-error");

  form.addEventListener("submit", async function (ev) {
    ev.preventDefault();
    err.hidden = true;
    const data = new FormData();
    const f = document.getElementById("ref-file").files[0];
    if (!f) { err.textContent = "Choose a BVH file."; err.hidden = false; return; }
    data.append("file", f, f.name);
    const name = document.getElementById("ref-name").value.trim();
    if (name) data.append("name", name);
    const d = document.getElementById("ref-domain").files[0];
    if (d) data.append("domain", d, d.name);
    const button = form.querySelector("button[type=submit]");
    button.disabled = true; button.textContent = "Importing…";
    try {
      await coach.api("/api/v1/references", { method: "POST", body: data });
      form.reset();
      await load();
    } catch (e) { err.textContent = e.message; err.hidden = false; }
    button.disabled = false; button.textContent = "Upload reference";
  });

  function boneValue(map, b, dflt) {
    if (!map) return dflt;
    const name = BONES[b], child = name.split("->")[1];
    if (map[name] != null) return map[name];
    if (map[child] != null) return map[child];
    return dflt;
  }

  function card(r) {
    const dom = r.domain || {};
    const id = "ref" + r.id;
    const names = r.segment_names.length ? r.segment_names : (dom.segment_names || []);
    const segInput = coach.el("textarea", { id: id + "-segs", rows: Math.min(Math.max(names.length, 2), 12) });
    segInput.value = names.join("\n");
    const nameInput = coach.el("input", { id: id + "-name", maxlength: 200, value: r.name });
    const dflt = coach.el("input", { id: id + "-dtol", type: "number", min: 0, max: 180, step: 1, value: dom.default_tolerance_deg || 0 });
    const grid = coach.el("div", { class: "weights", role: "group", "aria-label": "Per-bone weight and tolerance" }, [
      coach.el("span", { class: "head", text: "Bone" }), coach.el("span", { class: "head", text: "Weight" }), coach.el("span", { class: "head", text: "Tolerance °" })]);
    BONES.forEach(function (bone, b) {
      const w = coach.el("input", { type: "number", min: 0, max: 100, step: 0.5, value: boneValue(dom.bone_weights, b, 1), id: id + "-w" + b, "aria-label": bone + " weight", "data-bone": bone, class: "w" });
      const t = coach.el("input", { type: "number", min: 0, max: 180, step: 1, value: boneValue(dom.tolerances_deg, b, ""), placeholder: "default", id: id + "-t" + b, "aria-label": bone + " tolerance in degrees", "data-bone": bone, class: "t" });
      grid.append(coach.el("label", { for: id + "-w" + b, text: bone }), w, t);
    });
    const status = coach.el("p", { class: "saved", role: "status" });
    const f = coach.el("form", { class: "stack", "aria-label": "Edit " + r.name }, [
      coach.el("label", { for: id + "-name", text: "Name" }), nameInput,
      coach.el("label", { for: id + "-segs", text: "Segment names (" + (r.segment_names.length ? r.segment_names.length + " segments, " : "") + "one a line, in order)" }), segInput,
      coach.el("label", { for: id + "-dtol", text: "Default tolerance (degrees)" }), dflt,
      coach.el("details", {}, [coach.el("summary", { text: "Per-bone weights and tolerances" }), grid]),
      coach.el("button", { type: "submit", class: "primary", text: "Save" }), status,
    ]);
    f.addEventListener("submit", async function (ev) {
      ev.preventDefault();
      status.textContent = "";
      const weights = {}, tols = {};
      f.querySelectorAll("input.w").forEach(function (i) { if (i.value !== "" && +i.value !== 1) weights[i.dataset.bone] = +i.value; });
      f.querySelectorAll("input.t").forEach(function (i) { if (i.value !== "") tols[i.dataset.bone] = +i.value; });
      try {
        await coach.api("/api/v1/references/" + r.id + "/domain", { method: "PUT", json: {
          name: nameInput.value.trim() || null,
          segment_names: segInput.value.split("\n").map(function (s) { return s.trim(); }).filter(Boolean),
          bone_weights: weights, tolerances_deg: tols, default_tolerance_deg: +dflt.value || 0 } });
        status.className = "saved"; status.textContent = "Saved.";
      } catch (e) { status.className = "error"; status.textContent = e.message; }
    });
    return coach.el("section", { class: "card ref-card", "aria-labelledby": id + "-h" }, [
      coach.el("h2", { id: id + "-h", text: r.name }),
      coach.el("p", { class: "muted", text: (r.frames || "?") + " frames at " + (r.fps ? r.fps.toFixed(1) : "?") + " fps · " + (r.duration_s ? r.duration_s.toFixed(1) + " s" : "") }),
      coach.el("img", { src: r.strip, alt: "Postures of " + r.name + " at its segment boundaries" }),
      f,
    ]);
  }

  async function load() {
    const refs = (await coach.api("/api/v1/references?limit=100")).items;
    listEl.textContent = "";
    if (!refs.length) listEl.append(coach.el("p", { class: "muted", text: "No references yet." }));
    refs.forEach(function (r) { listEl.append(card(r)); });
  }
  load().catch(function (e) { listEl.textContent = e.message; });
})();
