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

  const videoErr = document.getElementById("video-error");
  const maxBytes = +form.dataset.maxBytes || 0;

  function showError(msg) { err.textContent = msg; err.hidden = false; }
  function mb(bytes) { return (bytes / 1e6).toFixed(bytes < 1e7 ? 1 : 0) + " MB"; }
  // A problem with the file itself: said next to the file input, and focus moved there, so a
  // keyboard or screen-reader user lands on the control that fixes it.
  function showVideoError(msg) {
    videoErr.textContent = msg;
    videoErr.hidden = false;
    drop.classList.add("invalid");
    input.setAttribute("aria-invalid", "true");
    input.focus();
  }
  function clearErrors() {
    err.hidden = true; videoErr.hidden = true;
    drop.classList.remove("invalid");
    input.removeAttribute("aria-invalid");
  }
  const FILE_ERRORS = ["invalid_video", "too_large", "unsupported_media_type", "video_too_long"];
  function apiMessage(status, body) {
    const e = body && body.error;
    if (!e) return status === 413 ? "The video is too large." : "Upload failed (" + status + ").";
    if (e.code === "too_large" && e.details && e.details.limit_bytes)
      return "The video is " + mb(file.size) + "; the limit is " + mb(e.details.limit_bytes) + ". Trim it or record at a lower resolution.";
    if (e.code === "invalid_video") return "This file cannot be analysed as a video: " + e.message + ".";
    return e.message.charAt(0).toUpperCase() + e.message.slice(1) + ".";
  }

  coach.api("/api/v1/references?limit=100").then(function (page) {
    const refs = page.items;
    list.textContent = "";
    if (!refs.length) { list.append(coach.el("p", { text: "No reference motions yet: ask your coach to add one." })); return; }
    refs.forEach(function (r, i) {
      const id = "ref-" + r.id;
      const k = r.segment_names.length;
      const unnamed = r.segment_names.every(function (s, j) { return s === "segment " + (j + 1); });
      const segs = k > 1 && unnamed ? k + " segments" : k ? r.segment_names.join(" · ") : "one segment";
      const radio = coach.el("input", { type: "radio", name: "reference_id", value: r.id, id: id });
      if (i === 0) radio.checked = true;
      const canvas = coach.el("canvas", { class: "ref-preview", width: 240, height: 120, role: "img",
        "aria-label": "Looping preview of " + r.name + ": front and side view" });
      list.append(coach.el("label", { class: "ref-option", for: id }, [
        radio,
        canvas,
        coach.el("span", { class: "name", text: r.name }),
        coach.el("span", { class: "segs", text: segs }),
        coach.el("span", { class: "segs", text: (r.duration_s ? r.duration_s.toFixed(1) + " s" : "") }),
      ]));
      preview(canvas, r);
    });
  }).catch(function (e) { list.textContent = ""; showError(e.message); });

  // A short looping preview of each reference: a few dozen sampled postures, drawn front and
  // side by side on a canvas (no libraries); a still frame for people who prefer less motion.
  const still = window.matchMedia && window.matchMedia("(prefers-reduced-motion: reduce)").matches;
  function preview(canvas, r) {
    coach.api(r.preview).then(function (p) {
      const ctx = canvas.getContext("2d");
      const dpr = window.devicePixelRatio || 1;
      canvas.width = 240 * dpr; canvas.height = 120 * dpr;
      ctx.scale(dpr, dpr);
      function draw(i) {
        ctx.fillStyle = "#f4f6fa"; ctx.fillRect(0, 0, 240, 120);
        ctx.fillStyle = "#5c6675"; ctx.font = "10px system-ui, sans-serif";
        ctx.fillText("front", 4, 11); ctx.fillText("side", 124, 11);
        ctx.strokeStyle = "#3b5bdb"; ctx.lineWidth = 2.5; ctx.lineCap = "round";
        [p.front[i], p.side[i]].forEach(function (j, v) {
          ctx.beginPath();
          p.bones.forEach(function (b) {
            ctx.moveTo(v * 120 + j[b[0]][0] * 120, j[b[0]][1] * 120);
            ctx.lineTo(v * 120 + j[b[1]][0] * 120, j[b[1]][1] * 120);
          });
          ctx.stroke();
        });
        canvas.dataset.frame = i;
      }
      canvas.dataset.ready = "true";
      if (still) { draw(Math.floor(p.frames / 2)); return; }
      const t0 = performance.now();
      let shown = -1;
      (function tick(now) {
        // rAF's timestamp is the frame's start, which can precede t0: clamp.
        const i = Math.floor(Math.max(now - t0, 0) / 1000 * p.fps) % p.frames;
        if (i !== shown && canvas.isConnected) { draw(i); shown = i; }
        if (canvas.isConnected) requestAnimationFrame(tick);
      })(t0);
    }).catch(function () { canvas.replaceWith(coach.el("img", { src: r.thumbnail, alt: "" })); });
  }

  function choose(f) {
    if (!f) return;
    clearErrors();
    fileName.textContent = f.name + " (" + mb(f.size) + ")";
    if (f.type && !f.type.startsWith("video/")) {
      file = null;
      showVideoError(f.name + " is not a video (it is " + f.type + "). Choose a video file, e.g. .mp4 or .mov.");
      return;
    }
    if (maxBytes && f.size > maxBytes) {
      file = null;
      showVideoError("The video is " + mb(f.size) + "; the limit is " + mb(maxBytes) + ". Trim it or record at a lower resolution.");
      return;
    }
    file = f;
    checkFraming(f);
  }

  // The filming check: the chosen video's first frame goes to the API as a picture before
  // anything is uploaded; what to change shows at once. A warning, never a block. Videos
  // this browser cannot decode (e.g. HEVC in some browsers) are checked by the engine instead:
  // the result's messages say what the first frame shows (engine/stages/framing.py).
  const check = document.getElementById("framing-check");
  let checking = 0;
  function firstFrame(f) {
    return new Promise(function (resolve, reject) {
      const v = document.createElement("video");
      const url = URL.createObjectURL(f);
      const done = function (fn, x) { URL.revokeObjectURL(url); v.removeAttribute("src"); fn(x); };
      v.muted = true; v.preload = "auto"; v.playsInline = true;
      v.addEventListener("error", function () { done(reject, new Error("undecodable")); });
      v.addEventListener("loadeddata", function () { v.currentTime = Math.min(0.05, (v.duration || 1) / 2); });
      v.addEventListener("seeked", function () {
        const c = document.createElement("canvas");
        const k = Math.min(1, 960 / Math.max(v.videoWidth, v.videoHeight));
        c.width = Math.round(v.videoWidth * k); c.height = Math.round(v.videoHeight * k);
        c.getContext("2d").drawImage(v, 0, 0, c.width, c.height);
        c.toBlob(function (b) { done(b ? resolve : reject, b || new Error("no picture")); }, "image/jpeg", 0.9);
      }, { once: true });
      v.src = url;
    });
  }
  async function checkFraming(f) {
    const mine = ++checking;
    check.hidden = false; check.className = "framing checking";
    check.dataset.state = "checking";
    check.textContent = "Checking how the video is filmed…";
    try {
      const data = new FormData();
      let picture;
      try { picture = await firstFrame(f); } catch (e) {
        if (mine !== checking) return;
        check.className = "framing"; check.dataset.state = "undecodable";
        check.textContent = "This browser cannot show this video, so its first frame is checked once it is uploaded: the result will say if something about the filming should change.";
        return;
      }
      data.append("frame", picture, "first-frame.jpg");
      const r = await coach.api("/api/v1/framing", { method: "POST", body: data });
      if (mine !== checking) return;  // another video was chosen meanwhile
      check.textContent = "";
      check.className = "framing " + (r.problems.length ? "warn" : "ok");
      check.dataset.state = r.problems.length ? "problems" : "ok";
      if (!r.problems.length) {
        check.append(coach.el("p", { text: "✓ First frame checked: one person, the whole body in view." }));
      } else {
        check.append(coach.el("p", { text: "⚠ Before you upload, the first frame suggests:" }),
          coach.el("ul", {}, r.problems.map(function (t) { return coach.el("li", { text: t }); })),
          coach.el("p", { class: "muted", text: "You can still upload it; the analysis may then be less reliable." }));
      }
    } catch (e) {
      if (mine !== checking) return;
      check.hidden = true; check.dataset.state = "unchecked";
    }
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
    clearErrors();
    const ref = form.querySelector("input[name=reference_id]:checked");
    if (!ref) { showError("Choose a reference motion first."); return; }
    if (!file) { showVideoError("Choose a video first."); return; }
    const data = new FormData();
    data.append("reference_id", ref.value);
    const performer = document.getElementById("performer");
    if (performer) data.append("performer_id", performer.value);
    data.append("video", file, file.name);
    const xhr = new XMLHttpRequest();
    xhr.open("POST", "/api/v1/analyses");
    xhr.setRequestHeader("Accept", "application/json");
    // A retry of the same file reuses the analysis instead of making a second one; the key
    // names everything sent, since the API refuses a key reused for another upload (409).
    xhr.setRequestHeader("Idempotency-Key", [file.name, file.size, file.lastModified, ref.value, performer ? performer.value : "", Date.now() >> 16].join(":").slice(0, 255));
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
        location.href = "/analyses/" + encodeURIComponent(body.id);
      } else {
        button.disabled = false;
        prog.hidden = true;
        const code = body && body.error ? body.error.code : (xhr.status === 413 ? "too_large" : "");
        const msg = apiMessage(xhr.status, body);
        if (FILE_ERRORS.indexOf(code) >= 0 || xhr.status === 413) showVideoError(msg); else showError(msg);
      }
    });
    xhr.addEventListener("error", function () { button.disabled = false; showError("The upload was interrupted; try again."); });
    button.disabled = true;
    prog.hidden = false;
    xhr.send(data);
  });
})();
