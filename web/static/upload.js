"use strict";
(function () {
  const form = document.getElementById("upload-form");
  const list = document.getElementById("references");
  const input = document.getElementById("video");
  const drop = document.getElementById("drop");
  const fileName = document.getElementById("file-name");
  const err = document.getElementById("upload-error");
  const button = document.getElementById("upload-button");
  const prog = document.getElementById("upload-progress");
  const bar = document.getElementById("upload-bar");
  const pct = document.getElementById("upload-pct");
  let file = null;

  function showError(msg) { err.textContent = msg; err.hidden = false; }

  coach.api("/web/api/references").then(function (refs) {
    list.textContent = "";
    if (!refs.length) { list.append(coach.el("p", { text: "No reference motions yet: ask your coach to add one." })); return; }
    refs.forEach(function (r, i) {
      const id = "ref-" + r.id;
      const segs = r.segment_names.length ? r.segment_names.join(" · ") : "one segment";
      const radio = coach.el("input", { type: "radio", name: "reference_id", value: r.id, id: id });
      if (i === 0) radio.checked = true;
      list.append(coach.el("label", { class: "ref-option", for: id }, [
        radio,
        coach.el("img", { src: r.thumbnail, alt: "", loading: "lazy" }),
        coach.el("span", { class: "name", text: r.name }),
        coach.el("span", { class: "segs", text: segs }),
        coach.el("span", { class: "segs", text: (r.duration_s ? r.duration_s.toFixed(1) + " s" : "") }),
      ]));
    });
  }).catch(function (e) { list.textContent = ""; showError(e.message); });

  function choose(f) {
    if (!f) return;
    if (f.type && !f.type.startsWith("video/")) { showError("That is not a video file."); return; }
    file = f;
    err.hidden = true;
    fileName.textContent = f.name + " (" + (f.size / 1e6).toFixed(1) + " MB)";
  }
  input.addEventListener("change", function () { choose(input.files[0]); });
  ["dragenter", "dragover"].forEach(function (t) {
    drop.addEventListener(t, function (e) { e.preventDefault(); drop.classList.add("over"); });
  });
  ["dragleave", "drop"].forEach(function (t) {
    drop.addEventListener(t, function (e) { e.preventDefault(); drop.classList.remove("over"); });
  });
  drop.addEventListener("drop", function (e) { choose(e.dataTransfer.files[0]); });

  form.addEventListener("submit", function (ev) {
    ev.preventDefault();
    err.hidden = true;
    const ref = form.querySelector("input[name=reference_id]:checked");
    if (!ref) { showError("Choose a reference motion first."); return; }
    if (!file) { showError("Choose a video first."); input.focus(); return; }
    const data = new FormData();
    data.append("reference_id", ref.value);
    const performer = document.getElementById("performer");
    if (performer) data.append("performer_id", performer.value);
    data.append("video", file, file.name);
    const xhr = new XMLHttpRequest();
    xhr.open("POST", "/web/api/analyses");
    xhr.setRequestHeader("Accept", "application/json");
    // A retry of the same file reuses the analysis instead of making a second one.
    xhr.setRequestHeader("Idempotency-Key", [file.name, file.size, file.lastModified, ref.value, Date.now() >> 16].join(":").slice(0, 255));
    xhr.upload.addEventListener("progress", function (e) {
      if (!e.lengthComputable) return;
      const p = Math.round(100 * e.loaded / e.total);
      bar.value = p; pct.textContent = p + " %";
    });
    xhr.addEventListener("load", function () {
      let body = null;
      try { body = JSON.parse(xhr.responseText); } catch (e) { body = null; }
      if (xhr.status === 200 || xhr.status === 201) {
        bar.value = 100; pct.textContent = "100 %";
        location.href = body.url;
      } else {
        button.disabled = false;
        showError(body && body.error ? body.error.message : "Upload failed (" + xhr.status + ").");
      }
    });
    xhr.addEventListener("error", function () { button.disabled = false; showError("The upload was interrupted; try again."); });
    button.disabled = true;
    prog.hidden = false;
    xhr.send(data);
  });
})();
