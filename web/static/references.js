// References (coach): upload a BVH through the page, preview its postures, edit the domain
// file (segment names, per-bone weights and tolerances).
"use strict";
(function () {
  const listEl = document.getElementById("ref-list");
  const BONES = JSON.parse(listEl.dataset.bones);
  const form = document.getElementById("ref-upload");
  const err = document.getElementById("ref-error");
  const done = document.getElementById("ref-done");

  form.addEventListener("submit", async function (ev) {
    ev.preventDefault();
    err.hidden = true; done.hidden = true;
    const data = new FormData();
    const files = Array.from(document.getElementById("ref-file").files);
    if (!files.length) { err.textContent = "Choose a BVH file."; err.hidden = false; return; }
    const d = document.getElementById("ref-domain").files[0];
    const takes = files.length > 1;  // several takes of one action: a reference from takes
    if (takes && d) { err.textContent = "A domain file goes with one BVH; a reference from takes gets its own. Set segment names after the upload."; err.hidden = false; return; }
    files.forEach(function (f) { data.append(takes ? "takes" : "file", f, f.name); });
    const name = document.getElementById("ref-name").value.trim();
    if (name) data.append("name", name);
    if (d) data.append("domain", d, d.name);
    const button = form.querySelector("button[type=submit]");
    button.disabled = true; button.textContent = takes ? "Synchronising " + files.length + " takes…" : "Importing…";
    try {
      const r = await coach.api(takes ? "/api/v1/references/takes" : "/api/v1/references", { method: "POST", body: data });
      done.textContent = "Added “" + r.name + "”: " + r.frames + " frames" + (takes ? ", from " + r.derived.takes.kept.length + " takes." : ".");
      done.hidden = false;
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

  // A reference built from several takes: which takes, the median, what was left out, the
  // synchronisation plot and the expert's spread per bone (mean and largest over the frames).
  function takesInfo(r) {
    const t = (r.derived || {}).takes;
    if (!t) return null;
    const rows = Object.keys(t.bone_sd_deg_mean).sort(function (a, b) { return t.bone_sd_deg_mean[b] - t.bone_sd_deg_mean[a]; })
      .map(function (b) { return coach.el("tr", {}, [coach.el("td", { text: coach.boneLabel(b) }), coach.el("td", { text: t.bone_sd_deg_mean[b].toFixed(1) + "°" }), coach.el("td", { text: t.bone_sd_deg_max[b].toFixed(1) + "°" })]); });
    return coach.el("div", { class: "takes" }, [
      coach.el("p", { text: "Built from " + t.kept.length + " takes (" + t.kept.join(", ") + "); time pattern: the median take " + t.median_take + "." }),
      t.warnings.length ? coach.el("ul", { class: "error" }, t.warnings.map(function (w) { return coach.el("li", { text: w }); })) : null,
      coach.el("img", { src: r.takes_plot, class: "takes-plot", alt: "The takes of " + r.name + " before and after synchronisation, and their mean with three standard deviations" }),
      coach.el("details", {}, [coach.el("summary", { text: "The expert's own variation per bone" }),
        coach.el("table", { class: "spread" }, [coach.el("thead", {}, [coach.el("tr", {}, [coach.el("th", { text: "Bone" }), coach.el("th", { text: "Mean spread" }), coach.el("th", { text: "Largest" })])]), coach.el("tbody", {}, rows)])]),
    ]);
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
      const label = coach.boneLabel(bone);
      const w = coach.el("input", { type: "number", min: 0, max: 100, step: 0.5, value: boneValue(dom.bone_weights, b, 1), id: id + "-w" + b, "aria-label": label + " weight", "data-bone": bone, class: "w" });
      const t = coach.el("input", { type: "number", min: 0, max: 180, step: 1, value: boneValue(dom.tolerances_deg, b, ""), placeholder: "default", id: id + "-t" + b, "aria-label": label + " tolerance in degrees", "data-bone": bone, class: "t" });
      grid.append(coach.el("label", { for: id + "-w" + b, text: label }), w, t);
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
    // Delete, after the coach confirms; a reference analyses use stays (the API says which).
    const gone = coach.el("p", { class: "error", role: "alert", hidden: "" });
    const del = coach.el("button", { type: "button", class: "danger", text: "Delete reference" });
    del.addEventListener("click", async function () {
      if (!confirm("Delete the reference " + r.name + "? Analyses can no longer use it. This cannot be undone.")) return;
      gone.hidden = true;
      try {
        await coach.api("/api/v1/references/" + r.id, { method: "DELETE" });
        await load();
        done.textContent = "Deleted “" + r.name + "”."; done.hidden = false;
      } catch (e) {
        gone.textContent = e.status === 409 ? "Analyses use this reference: delete them first, then the reference." : e.message;
        gone.hidden = false;
      }
    });
    return coach.el("section", { class: "card ref-card", "aria-labelledby": id + "-h" }, [
      coach.el("h2", { id: id + "-h", text: r.name }),
      coach.el("p", { class: "muted", text: (r.frames || "?") + " frames at " + (r.fps ? r.fps.toFixed(1) : "?") + " fps · " + (r.duration_s ? r.duration_s.toFixed(1) + " s" : "") }),
      coach.el("img", { src: r.strip, alt: "Postures of " + r.name + " at its segment boundaries" }),
      takesInfo(r),  // null (skipped) for a reference from one BVH
      f,
      coach.el("div", { class: "ref-delete" }, [del, gone]),
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
