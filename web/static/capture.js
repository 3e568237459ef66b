// 3D capture pages: the upload form and list (/captures), one capture (/captures/{id}):
// progress, the questions the video leaves open, downloads, "use as reference".
"use strict";
(function () {
  const root = document.getElementById("captures");
  const id = root.dataset.id;
  const $ = function (s) { return document.getElementById(s); };

  if (!id) {
    list();
    $("capture-form").addEventListener("submit", upload);
    return;
  }
  const base = "/api/v1/captures/" + id;
  const answers = {};
  poll();

  async function list() {
    const box = $("capture-list");
    try {
      const page = await coach.api("/api/v1/captures?limit=50");
      box.replaceChildren(...(page.items.length ? page.items.map(function (c) {
        return coach.el("li", {}, [coach.el("a", { href: "/captures/" + c.id, text: c.name }),
          coach.el("span", { class: "muted", text: " · " + c.status + " · " + new Date(c.created_at).toLocaleString() })]);
      }) : [coach.el("li", { class: "muted", text: "No captures yet." })]));
    } catch (e) { box.replaceChildren(coach.el("li", { class: "error", text: e.message })); }
  }

  async function upload(ev) {
    ev.preventDefault();
    const err = $("capture-form-error");
    err.hidden = true;
    const file = $("capture-file").files[0];
    if (!file) { err.textContent = "Choose a video first."; err.hidden = false; return; }
    const data = new FormData();
    const performer = $("performer");
    if (performer) data.append("performer_id", performer.value);
    data.append("height_m", $("height").value);
    data.append("video", file, file.name);
    $("capture-button").disabled = true;
    try {
      const r = await fetch("/api/v1/captures", { method: "POST", body: data, credentials: "same-origin", headers: { Accept: "application/json" } });
      const body = await r.json().catch(function () { return null; });
      if (!r.ok) throw new Error(body && body.error ? body.error.message : "upload failed (" + r.status + ")");
      location.href = "/captures/" + encodeURIComponent(body.id);
    } catch (e) {
      err.textContent = e.message; err.hidden = false;
      $("capture-button").disabled = false;
    }
  }

  async function poll() {
    let c;
    try { c = await coach.api(base); } catch (e) { showError(e.message); return; }
    $("capture-title").textContent = "3D capture: " + c.name;
    $("capture-status").textContent = c.status === "done" ? "Done: " + c.message : c.message || c.status;
    $("capture-bar").value = Math.round(100 * (c.status === "done" ? 1 : c.progress));
    if (c.status === "failed") { showError(c.error || c.message); return; }
    if (c.status !== "done") { setTimeout(poll, 1000); return; }
    $("capture-progress").hidden = true;
    show(c);
  }

  function showError(msg) { const e = $("capture-error"); e.textContent = msg; e.hidden = false; }

  function show(c) {
    $("capture-done").hidden = false;
    const video = $("capture-video");
    if (!video.src) video.src = base + "/video.mp4";
    $("dl-bvh").href = base + "/motion.bvh";
    $("dl-bvh-coach").href = base + "/motion.bvh?skeleton=coach";
    $("dl-csv").href = base + "/angles.csv";
    const name = $("reference-name");
    if (name && !name.value) name.value = c.name.replace(/\.[^.]+$/, "");
    if (c.reference_id && $("reference-done")) referenceDone(c.reference_id);
    $("questions").hidden = c.questions.length === 0;
    $("question-list").replaceChildren(...c.questions.map(function (q) { return question(q, c.fps || 30); }));
  }

  function question(q, fps) {
    const facing = q.segment === "facing";
    const options = facing ? [["yes", "Yes"], ["no", "No"]] : [["towards", "Towards the camera"], ["away", "Away from the camera"]];
    const chosen = facing ? (q.chosen === "towards" ? "yes" : "no") : q.chosen;
    const buttons = options.map(function (o) {
      return coach.el("label", { class: "choice" }, [coach.el("input", { type: "radio", name: q.id, value: o[0],
        onchange: function () { answers[q.id] = o[0]; } }), document.createTextNode(" " + o[1] + (o[0] === chosen ? " (our guess)" : ""))]);
    });
    const seek = coach.el("button", { type: "button", class: "link", text: "show me",
      onclick: function () { const v = $("capture-video"); v.pause(); v.currentTime = (q.frames[0] + 0.5) / fps; } });
    return coach.el("li", { "data-question": q.id }, [coach.el("p", { text: q.text }), seek, coach.el("div", {}, buttons)]);
  }

  $("send-answers").addEventListener("click", async function () {
    if (Object.keys(answers).length === 0) { showError("Pick an answer first."); return; }
    this.disabled = true;
    try {
      await coach.api(base + "/answers", { method: "POST", json: { answers: answers } });
      $("capture-done").hidden = true; $("capture-progress").hidden = false;
      poll();
    } catch (e) { showError(e.message); this.disabled = false; }
  });

  const form = $("to-reference");
  if (form) form.addEventListener("submit", async function (ev) {
    ev.preventDefault();
    try {
      const ref = await coach.api(base + "/reference", { method: "POST", json: { name: $("reference-name").value } });
      referenceDone(ref.id);
    } catch (e) { showError(e.message); }
  });
  function referenceDone(refId) {
    const p = $("reference-done");
    p.replaceChildren(document.createTextNode("In the reference library. "), coach.el("a", { href: "/upload", text: "Analyse a video against it" }));
    p.hidden = false;
    p.dataset.reference = String(refId);
  }
})();
