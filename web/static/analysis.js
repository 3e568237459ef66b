// One analysis: live progress (SSE, polling fallback), then the results: video with the
// skeleton overlay, the 3D view, one shared timeline (error plot + cursor), segment cards,
// comments pinned to frames or segments.
"use strict";
(function () {
  const root = document.getElementById("analysis");
  const id = root.dataset.id;
  const review = root.dataset.review === "true";
  const base = "/api/v1/analyses/" + id;
  const $ = function (s) { return document.getElementById(s); };
  const SVGNS = "http://www.w3.org/2000/svg";
  // This tab's own 3D view: the token in its frame's address (web/viewer/proxy.py); seeking
  // here moves this tab's view only. getRandomValues works on plain http too.
  const TAB = Array.from(crypto.getRandomValues(new Uint8Array(16)), function (b) { return b.toString(16).padStart(2, "0"); }).join("");
  // The bones in the result's order, in a coach's words (one table, served with the page).
  const BONES = coach.BONE_IDS.map(function (_, b) { return coach.boneLabel(b); });
  const PARENT = [0, 1, 2, 0, 4, 5, 0, 7, 8, 9, 10, 8, 12, 13, 8, 15];
  const CHILD = [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16];
  const PALETTE = ["#1971c2", "#9c36b5", "#e67700", "#0c8599", "#5f3dc4", "#d6336c", "#2f9e44", "#495057"];
  const MISFIT = "#fab005";
  const EXPERT_GHOST = "rgba(110,130,200,0.85)";  // the expert in the video, as in the 3D view  // shading of frames the video does not confirm (image_misfit)
  function capital(t) { return t.charAt(0).toUpperCase() + t.slice(1); }
  // Degrees for people: one decimal under 10 (a segment at 0.4 deg is not "0 deg").
  function deg(v) { return (Math.abs(v) < 9.95 ? v.toFixed(1) : v.toFixed(0)) + "°"; }

  // ---------------------------------------------------------------- progress
  const seenStages = [];
  // What each pipeline stage does, in the performer's words (worker and engine stage names).
  const STAGE_TEXT = {
    queued: "Waiting for a free worker",
    prepare: "Preparing",
    perception: "Finding your body and joints",
    foreground: "Separating you from the background",
    calibration: "Calibrating the camera",
    alignment: "Matching your timing to the expert's",
    candidates: "Finding possible postures, frame by frame",
    select: "Choosing postures and measuring the differences",
    selection: "Choosing postures and measuring the differences",
  };
  function stageText(s) { return STAGE_TEXT[s] || s; }
  function showProgress(a) {
    root.dataset.status = a.status;
    const pct = Math.round(100 * (a.progress || 0));
    $("stage-name").textContent = stageText(a.stage || a.status);
    $("stage-pct").textContent = pct + " % overall";
    $("stage-bar").value = pct;
    $("stage-message").textContent = a.message || "";
    const current = a.stage ? stageText(a.stage) : "";
    if (current && seenStages.indexOf(current) < 0) seenStages.push(current);
    const ol = $("stage-list");
    ol.textContent = "";
    seenStages.forEach(function (s) {
      const done = a.status === "done" || s !== current;
      ol.append(coach.el("li", { class: done ? "done" : "current", text: (done ? "✓ " : "") + s }));
    });
    if (a.error) { $("analysis-error").textContent = a.error; $("analysis-error").hidden = false; }
    showWarnings(a.warnings || []);
    $("cancel").hidden = !(a.status === "queued" || a.status === "running");
    // The live 3D view exists once stage 2 has aligned the expert: ask for it only then.
    if (a.status === "running" && LIVE_STAGES.indexOf(a.stage) >= 0) followLive();
    if (a.status === "running" && a.stage === "candidates") followFirstResults();
  }
  // While stage 3 works on the rest of the video, stage 4 runs on the segments it has
  // finished (engine/provisional.py): their cards show here until the final result.
  let firstTimer = null, firstShown = 0;
  function followFirstResults() {
    if (firstTimer) return;
    async function step() {
      try {
        const p = await coach.api(base + "/provisional");
        if (p.provisional.segments === firstShown) return;
        firstShown = p.provisional.segments;
        const k = p.provisional.segments, of = p.provisional.reference_segments;
        $("first-results-note").textContent = (k === 1 ? "The first of " + of + " segments is" : "The first " + k + " of " + of + " segments are") +
          " analysed (frames 0–" + (p.provisional.frames - 1) + " of " + p.provisional.video_frames +
          "). Provisional: the figures may change a little when the whole video is done.";
        const box = $("first-cards");
        box.textContent = "";
        p.segments.forEach(function (s) {
          const card = coach.el("div", { class: "seg-card provisional" }, segmentHead(s).concat([
            coach.el("ul", {}, s.worst_bones.map(function (wb) { return coach.el("li", { text: wb[0] + ": " + deg(wb[1]) }); })),
          ]));
          card.style.borderLeftColor = coach.errorColor(s.mean_error_deg);
          box.append(card);
        });
        $("first-results").hidden = false;
      } catch (e) {
        if (e.status !== 409) stopFirstResults();  // 409: no whole segment yet, or done
      }
    }
    firstTimer = setInterval(step, 2000);
    step();
  }
  function stopFirstResults() {
    if (firstTimer) { clearInterval(firstTimer); firstTimer = null; }
    $("first-cards").textContent = "";  // the final cards replace them
    $("first-results").hidden = true;
  }
  // What the first frame says about the filming, known once stages 0-2 are done: the upload
  // page checks it only for videos this browser can decode (engine/stages/framing.py).
  let warningsShown = "";
  function showWarnings(list) {
    const key = list.join("\n");
    if (key === warningsShown) return;
    warningsShown = key;
    const box = $("framing-warnings"), ul = box.querySelector("ul");
    ul.textContent = "";
    list.forEach(function (t) { ul.append(coach.el("li", { text: t })); });
    box.hidden = !list.length;
  }
  const LIVE_STAGES = ["candidates", "select", "selection"];
  // While it runs, the 3D view fills in: the aligned expert after stage 2, the best candidate
  // of each frame as stage 3 finishes it, colours when stage 4 is done (web/viewer/partial.py).
  const LIVE_TEXT = {
    reference: "3D: the expert aligned to your video (stage 2); candidates follow.",
    candidates: "3D: best candidate postures for {done} of {n} frames (stage 3).",
    done: "3D: finished; colours show each bone's error.",
  };
  let liveTimer = null, liveBusy = false;
  function followLive() {
    if (liveTimer) return;
    const fig = $("live3d"), iframe = $("live-viewer3d");
    async function step() {
      if (liveBusy) return;
      liveBusy = true;
      try {
        const v = await coach.api(base + "/viewer/live", { method: "POST" });
        if (!iframe.getAttribute("src")) iframe.src = v.url + TAB + "/";
        if (fig.hidden) { fig.hidden = false; fitFrame(iframe); }
        fig.dataset.phase = v.phase;
        fig.dataset.framesDone = String(v.frames_done);
        $("live3d-status").textContent = (LIVE_TEXT[v.phase] || "").replace("{done}", v.frames_done).replace("{n}", v.frames);
      } catch (e) {
        if (e.status !== 409) { stopLive(); }  // 409: stage 2's files are not written yet
      } finally { liveBusy = false; }
    }
    liveTimer = setInterval(step, 1000);
    step();
  }
  function stopLive() {
    if (liveTimer) { clearInterval(liveTimer); liveTimer = null; }
    const iframe = $("live-viewer3d");
    if (iframe.getAttribute("src")) iframe.src = "about:blank";  // drop its connection
    $("live3d").hidden = true;
  }
  function finished(status) {
    stopLive();
    stopFirstResults();
    if (status === "done") { $("progress-view").hidden = true; loadResults(); }
    else { $("stage-message").textContent = "The analysis " + status + "."; $("cancel").hidden = true; }
  }
  let polling = null;
  function poll() {
    if (polling) return;
    polling = setInterval(async function () {
      try {
        const a = await coach.api(base);
        showProgress(a);
        if (["done", "failed", "cancelled"].indexOf(a.status) >= 0) { clearInterval(polling); finished(a.status); }
      } catch (e) { /* keep polling through blips */ }
    }, 2000);
  }
  function follow() {
    if (!window.EventSource) { poll(); return; }
    const es = new EventSource(base + "/events");
    es.addEventListener("progress", function (ev) { showProgress(JSON.parse(ev.data)); });
    es.addEventListener("end", function (ev) { es.close(); finished(JSON.parse(ev.data).status); });
    es.onerror = function () { es.close(); poll(); };
  }
  $("cancel").addEventListener("click", async function () {
    try { showProgress(await coach.api(base + "/cancel", { method: "POST" })); } catch (e) { $("stage-message").textContent = e.message; }
  });

  // ---------------------------------------------------------------- results
  const video = $("video"), overlay = $("overlay");
  let result = null, summary = null, frame = 0, fps = 30, n = 0, plot = null, viewerReady = false;
  // The analysed frames may be one repetition of several: result frame i is file frame
  // first + i, and the video outside them is shown without a skeleton.
  let first = 0, outside = false;

  async function loadResults() {
    $("results").hidden = false;
    [result, summary] = await Promise.all([coach.api(base + "/result"), coach.api(base + "/summary")]);
    fps = result.video.fps; n = result.frames.length; first = result.frames[0].t;
    overlay.width = result.video.width; overlay.height = result.video.height;
    video.src = base + "/video.mp4";
    showMessages((result.summary && result.summary.messages) || []);
    showRepetitions((result.summary && result.summary.repetitions) || []);
    const anyBest = result.frames.some(function (f) { return f.image_best_joints_2d; });
    $("legend-image-best").hidden = !anyBest;
    $("legend3d-image-best").hidden = !anyBest;
    $("expert-toggle").hidden = !result.frames.every(function (f) { return f.expert_joints_2d; });
    $("side-toggle").hidden = $("expert-toggle").hidden;
    $("side-canvas").width = result.video.width; $("side-canvas").height = result.video.height;
    buildBonePicks(); buildPlot(); buildSegments(); buildKeyPositions(); loadComments(); start3d(); loadAngles();
    $("plot").setAttribute("aria-valuemax", String(n - 1));
    setFrame(0, true);
    root.dataset.ready = "true";
  }

  // The engine's overall messages (missing segments, a very different performance, frames
  // the video does not confirm) come first: they qualify every number below.
  function showMessages(messages) {
    const box = $("result-messages");
    box.replaceChildren(...messages.map(function (m) { return coach.el("li", { text: m }); }));
    box.hidden = messages.length === 0;
  }

  // The repetitions the video holds when more than one; the analysed one is marked, the
  // others can be watched (without a skeleton: they are not analysed).
  function showRepetitions(reps) {
    const box = $("repetitions");
    box.hidden = reps.length === 0;
    $("repetition-list").replaceChildren(...reps.map(function (r, i) {
      const text = "Repetition " + (i + 1) + ": " + r.start_s.toFixed(1) + "–" + r.end_s.toFixed(1) + " s" + (r.analysed ? " (analysed)" : "");
      const watch = coach.el("button", { type: "button", class: "link" + (r.analysed ? " current" : ""), text: text,
        onclick: function () { video.pause(); if (video.readyState > 0) video.currentTime = (r.start + 0.5) / fps; } });
      const analyse = r.analysed ? null : coach.el("button", { type: "button", class: "small", text: "Analyse this one",
            "aria-label": "Analyse repetition " + (i + 1), onclick: function () { analyseRepetition(i + 1, this); } });
      return coach.el("li", {}, [watch, analyse]);
    }));
  }
  // A new analysis of the same video, limited to repetition n; its page takes over.
  async function analyseRepetition(n, button) {
    button.disabled = true;
    try {
      const created = await coach.api(base + "/repetitions/" + n, { method: "POST" });
      window.location.href = "/analyses/" + created.id;
    } catch (e) {
      button.disabled = false;
      button.textContent = "Could not start: " + e.message;
    }
  }
  function frameAtTime(t) {
    const raw = Math.floor(t * fps + 1e-3);
    outside = raw < first || raw > first + n - 1;
    return Math.max(0, Math.min(n - 1, raw - first));
  }
  function seek(f) {
    f = Math.max(0, Math.min(n - 1, f));
    outside = false;
    if (video.readyState > 0) video.currentTime = (f + first + 0.5) / fps;
    setFrame(f, true);
  }
  function setFrame(f, force) {
    if (f === frame && !force && !outside) return;
    frame = f;
    root.dataset.frame = String(f);
    const shown = outside ? Math.floor(video.currentTime * fps + 1e-3) : f + first;
    $("frame-label").textContent = "frame " + shown + " / " + (first + n - 1) + " · " + (shown / fps).toFixed(2) + " s" + (outside ? " · not analysed" : "");
    drawOverlay(); drawSide(); moveCursor(); markSegment(); sync3d(); showAngle();
  }
  function tick() {
    if (loopSegment()) { requestAnimationFrame(tick); return; }
    setFrame(frameAtTime(video.currentTime));
    if (!video.paused && !video.ended) requestAnimationFrame(tick);
  }
  video.addEventListener("play", function () { $("play").textContent = "Pause"; requestAnimationFrame(tick); });
  video.addEventListener("pause", function () { $("play").textContent = "Play"; tick(); });
  video.addEventListener("ended", function () { $("play").textContent = "Play"; });
  video.addEventListener("seeked", tick);
  video.addEventListener("timeupdate", tick);
  $("play").addEventListener("click", function () { if (video.paused) video.play(); else video.pause(); });
  $("prev").addEventListener("click", function () { video.pause(); seek(frame - 1); });
  $("next").addEventListener("click", function () { video.pause(); seek(frame + 1); });
  $("show-skeleton").addEventListener("change", drawOverlay);
  $("show-expert").addEventListener("change", function () { $("legend-expert").hidden = !$("show-expert").checked; drawOverlay(); });
  $("speed").addEventListener("change", function () { video.playbackRate = +$("speed").value; });
  // A-B loop over the segment the frame is in: playing past its end starts it again.
  function loopSegment() {
    if (!$("loop-segment").checked || !summary || video.paused) return false;
    const t = frameAtTime(video.currentTime) + first;
    const seg = summary.segments.find(function (s) { return frame + first >= s.performer_start && frame + first <= s.performer_end; });
    if (!seg || t <= seg.performer_end) return false;
    video.currentTime = (seg.performer_start + 0.5) / fps;
    return true;
  }

  function drawOverlay() { drawScene(); drawNotes(); }
  function drawScene() {
    const ctx = overlay.getContext("2d");
    ctx.clearRect(0, 0, overlay.width, overlay.height);
    if (!result || outside) return;
    const fr = result.frames[frame];
    const p = fr.joints_2d, e = fr.bone_errors_deg;
    const w = Math.max(2, overlay.height / 80);
    ctx.lineCap = "round";
    // The expert's posture at the matched reference frame, where the performer stands.
    const x = $("show-expert").checked && fr.expert_joints_2d;
    if (x) {
      ctx.strokeStyle = EXPERT_GHOST; ctx.lineWidth = w * 1.6;
      for (let b = 0; b < 16; b++) {
        ctx.beginPath(); ctx.moveTo(x[PARENT[b]][0], x[PARENT[b]][1]); ctx.lineTo(x[CHILD[b]][0], x[CHILD[b]][1]); ctx.stroke();
      }
    }
    if (!$("show-skeleton").checked) return;
    for (let b = 0; b < 16; b++) {
      ctx.strokeStyle = "rgba(0,0,0,0.6)"; ctx.lineWidth = w + 2;
      ctx.beginPath(); ctx.moveTo(p[PARENT[b]][0], p[PARENT[b]][1]); ctx.lineTo(p[CHILD[b]][0], p[CHILD[b]][1]); ctx.stroke();
      ctx.strokeStyle = coach.errorColor(e[b]); ctx.lineWidth = w;
      ctx.beginPath(); ctx.moveTo(p[PARENT[b]][0], p[PARENT[b]][1]); ctx.lineTo(p[CHILD[b]][0], p[CHILD[b]][1]); ctx.stroke();
    }
    ctx.fillStyle = "#fff";
    p.forEach(function (q) { ctx.beginPath(); ctx.arc(q[0], q[1], w * 0.6, 0, 2 * Math.PI); ctx.fill(); });
    const measured = angleBend();
    if (measured) {  // the joint being measured: a ring around it
      const q = p[measured.joint];
      ctx.strokeStyle = "#fff"; ctx.lineWidth = w * 0.6;
      ctx.beginPath(); ctx.arc(q[0], q[1], w * 3, 0, 2 * Math.PI); ctx.stroke();
    }
    // Where the video disagrees: the posture that fits the video best, dashed.
    const g = fr.image_best_joints_2d;
    if (!g) return;
    ctx.setLineDash([w * 2, w * 1.5]);
    ctx.strokeStyle = MISFIT; ctx.lineWidth = w;
    for (let b = 0; b < 16; b++) {
      ctx.beginPath(); ctx.moveTo(g[PARENT[b]][0], g[PARENT[b]][1]); ctx.lineTo(g[CHILD[b]][0], g[CHILD[b]][1]); ctx.stroke();
    }
    ctx.setLineDash([]);
  }

  // ---------------------------------------------------------------- timeline
  function picked() {
    return Array.from(document.querySelectorAll("#bone-picks input:checked")).map(function (i) { return +i.value; });
  }
  function buildBonePicks() {
    const mean = BONES.map(function (_, b) {
      return result.frames.reduce(function (s, f) { return s + f.bone_errors_deg[b]; }, 0) / n;
    });
    const worst = mean.map(function (m, b) { return [m, b]; }).sort(function (a, b) { return b[0] - a[0]; }).slice(0, 2).map(function (x) { return x[1]; });
    const box = $("bone-picks");
    BONES.forEach(function (name, b) {
      const cb = coach.el("input", { type: "checkbox", value: b, id: "bone-" + b });
      cb.checked = worst.indexOf(b) >= 0;
      cb.addEventListener("change", buildPlot);
      box.append(coach.el("label", { class: "inline", for: "bone-" + b }, [cb, document.createTextNode(name + " (mean " + deg(mean[b]) + ")")]));
    });
  }
  function svg(tag, attrs) {
    const e = document.createElementNS(SVGNS, tag);
    for (const k in attrs) e.setAttribute(k, attrs[k]);
    return e;
  }
  function buildPlot() {
    const W = 1000, H = 200, L = 40, R = 8, T = 10, B = 24;
    const bones = picked();
    let most = 0;
    result.frames.forEach(function (f) {
      most = Math.max(most, f.posture_error_deg);
      bones.forEach(function (b) { most = Math.max(most, f.bone_errors_deg[b]); });
    });
    // The axis fits the curves, so small errors still show which frames stand out; its four
    // grid steps are whole degrees (the same heights as PLOT_TOPS in web/pages/media.py).
    const top = [4, 8, 12, 20, 40, 60, 80, 120, 180].find(function (v) { return v >= most * 1.1; }) || 180;
    const x = function (i) { return L + (W - L - R) * i / Math.max(n - 1, 1); };
    const y = function (v) { return T + (H - T - B) * (1 - v / top); };
    const s = svg("svg", { viewBox: "0 0 " + W + " " + H, preserveAspectRatio: "none", id: "plot-svg" });
    (summary.segments || []).forEach(function (seg, i) {
      const a = seg.performer_start - first, b = seg.performer_end - first;
      s.append(svg("rect", { x: x(a), y: T, width: Math.max(x(b) - x(a), 1), height: H - T - B, fill: i % 2 ? "#eef2fb" : "#f8f9fc" }));
      const t = svg("text", { x: x(a) + 4, y: T + 12, "font-size": 11, fill: "#5c6675" });
      t.textContent = seg.name; s.append(t);
    });
    // Frames the video does not confirm (flag image_misfit): their errors may be too small.
    const misfit = result.frames.map(function (f) { return (f.flags || []).indexOf("image_misfit") >= 0; });
    const step = (W - L - R) / Math.max(n - 1, 1);
    misfit.forEach(function (bad, i) {
      if (!bad) return;
      s.append(svg("rect", { x: x(i) - step / 2, y: T, width: step, height: H - T - B, fill: MISFIT, "fill-opacity": 0.35, class: "misfit-mark" }));
    });
    for (let v = 0; v <= top; v += top / 4) {
      s.append(svg("line", { x1: L, x2: W - R, y1: y(v), y2: y(v), stroke: "#e3e6ec" }));
      const t = svg("text", { x: 4, y: y(v) + 4, "font-size": 11, fill: "#5c6675" }); t.textContent = Math.round(v) + "°"; s.append(t);
    }
    // A reference built from several takes: the expert's own spread at each matched frame,
    // as a band from 0 (errors under it are within the expert's take-to-take variation).
    const EXPERT = "#2f9e44";
    const spreadBand = result.frames.every(function (f) { return f.expert_spread_deg != null; });
    if (spreadBand) {
      const upper = result.frames.map(function (f, i) { return x(i).toFixed(1) + "," + y(Math.min(f.expert_spread_deg, top)).toFixed(1); });
      const base = [x(n - 1).toFixed(1) + "," + y(0).toFixed(1), x(0).toFixed(1) + "," + y(0).toFixed(1)];
      const band = svg("polygon", { points: upper.concat(base).join(" "), fill: EXPERT, "fill-opacity": 0.18, class: "expert-band" });
      const title = svg("title", {}); title.textContent = "the expert's own variation (mean spread of the bones over the expert's takes)"; band.append(title);
      s.append(band);
    }
    function line(vals, colour, width, name) {
      const pts = vals.map(function (v, i) { return x(i).toFixed(1) + "," + y(v).toFixed(1); }).join(" ");
      const pl = svg("polyline", { points: pts, fill: "none", stroke: colour, "stroke-width": width, "vector-effect": "non-scaling-stroke" });
      const title = svg("title", {}); title.textContent = name; pl.append(title);
      s.append(pl);
    }
    // Each plotted bone's range over the candidates the video cannot tell apart, as a band.
    if (result.frames.every(function (f) { return f.bone_error_range_deg; })) {
      bones.forEach(function (b, k) {
        const edge = function (j) { return result.frames.map(function (f, i) { return x(i).toFixed(1) + "," + y(Math.min(f.bone_error_range_deg[b][j], top)).toFixed(1); }); };
        s.append(svg("polygon", { points: edge(1).concat(edge(0).reverse()).join(" "), fill: PALETTE[k % PALETTE.length], "fill-opacity": 0.12, class: "range-band" }));
      });
    }
    bones.forEach(function (b, k) { line(result.frames.map(function (f) { return f.bone_errors_deg[b]; }), PALETTE[k % PALETTE.length], 1.5, BONES[b]); });
    line(result.frames.map(function (f) { return f.posture_error_deg; }), "#c92a2a", 3, "posture error");
    const cursor = svg("line", { id: "plot-cursor", y1: T, y2: H - B, stroke: "#111", "stroke-width": 2, "vector-effect": "non-scaling-stroke" });
    s.append(cursor);
    const lt = svg("text", { x: L, y: H - 6, "font-size": 11, fill: "#5c6675" }); lt.textContent = "frame " + first; s.append(lt);
    const rt = svg("text", { x: W - R - 70, y: H - 6, "font-size": 11, fill: "#5c6675" }); rt.textContent = "frame " + (first + n - 1); s.append(rt);
    // Legend.
    let lx = L + 200;
    const items = [["posture error", "#c92a2a"]].concat(bones.map(function (b, k) { return [BONES[b], PALETTE[k % PALETTE.length]]; }));
    if (misfit.some(Boolean)) items.push(["video disagrees", MISFIT]);
    if (spreadBand) items.push(["expert's own variation", EXPERT]);
    items.forEach(function (it) {
      s.append(svg("rect", { x: lx, y: H - 15, width: 14, height: 4, fill: it[1] }));
      const t = svg("text", { x: lx + 18, y: H - 10, "font-size": 11, fill: "#333" }); t.textContent = it[0]; s.append(t);
      lx += 30 + it[0].length * 6;
    });
    plot = { x: x, L: L, R: R, W: W };
    $("plot").textContent = "";
    $("plot").append(s);
    moveCursor();
  }
  function moveCursor() {
    const c = document.getElementById("plot-cursor");
    if (!c || !plot) return;
    c.setAttribute("x1", plot.x(frame)); c.setAttribute("x2", plot.x(frame));
    $("plot").setAttribute("aria-valuenow", String(frame));
    $("plot").setAttribute("aria-valuetext", "frame " + frame);
  }
  function plotFrame(ev) {
    const r = $("plot").getBoundingClientRect();
    const u = (ev.clientX - r.left) / r.width * plot.W;
    return Math.round((u - plot.L) / (plot.W - plot.L - plot.R) * (n - 1));
  }
  let dragging = false;
  $("plot").addEventListener("pointerdown", function (ev) { if (!plot) return; dragging = true; video.pause(); seek(plotFrame(ev)); });
  $("plot").addEventListener("pointermove", function (ev) { if (dragging) seek(plotFrame(ev)); });
  window.addEventListener("pointerup", function () { dragging = false; });
  $("plot").addEventListener("keydown", function (ev) {
    const step = { ArrowLeft: -1, ArrowRight: 1, PageDown: -10, PageUp: 10 }[ev.key];
    if (step) { ev.preventDefault(); video.pause(); seek(frame + step); }
    if (ev.key === "Home") { ev.preventDefault(); seek(0); }
    if (ev.key === "End") { ev.preventDefault(); seek(n - 1); }
  });

  // ---------------------------------------------------------------- side by side
  // The expert beside your video, drawn in your camera at the matched moment: it is drawn
  // from the same frame as the overlay, so pausing, stepping and scrubbing stay in step.
  function drawSide() {
    const c = $("side-canvas");
    if ($("side-box").hidden || !result) return;
    const ctx = c.getContext("2d");
    ctx.fillStyle = "#1d2330"; ctx.fillRect(0, 0, c.width, c.height);
    c.dataset.frame = String(frame);
    const x = !outside && result.frames[frame].expert_joints_2d;
    if (!x) return;
    const w = Math.max(3, c.height / 60);
    ctx.strokeStyle = EXPERT_GHOST; ctx.lineWidth = w; ctx.lineCap = "round";
    for (let b = 0; b < 16; b++) {
      ctx.beginPath(); ctx.moveTo(x[PARENT[b]][0], x[PARENT[b]][1]); ctx.lineTo(x[CHILD[b]][0], x[CHILD[b]][1]); ctx.stroke();
    }
    ctx.fillStyle = EXPERT_GHOST;
    ctx.beginPath(); ctx.arc(x[16][0], x[16][1], w * 1.4, 0, 2 * Math.PI); ctx.fill();
  }
  $("show-side").addEventListener("change", function () {
    $("side-box").hidden = !$("show-side").checked;
    document.querySelector(".video-wrap").classList.toggle("side", $("show-side").checked);
    drawSide();
  });

  // ---------------------------------------------------------------- joint angles
  // Click a joint on the video (or pick it in the list): its bend now, yours and the
  // expert's at the matched moment (API /angles; 0 deg is a straight joint).
  let angles = null;
  async function loadAngles() {
    try { angles = await coach.api(base + "/angles"); } catch (e) { return; }
    const sel = $("angle-joint");
    angles.bends.forEach(function (b, k) {
      sel.append(coach.el("option", { value: String(k), text: capital(b.label) }));
    });
    showPosture();
  }
  function angleBend() {
    const k = $("angle-joint").value;
    return angles && k !== "" ? Object.assign({ index: +k }, angles.bends[+k]) : null;
  }
  // How the body stands: the spine's tilt from the vertical and the shoulders' and hips'
  // turn since the first frame, yours and the expert's (API /angles, engine/body/posture_angles.py).
  function showPosture() {
    const out = $("posture-readout");
    if (!angles || !angles.performer_posture || outside || !angles.performer_posture[frame]) { out.textContent = ""; return; }
    const you = angles.performer_posture[frame], them = angles.expert_posture[frame];
    const tilt = function (v, pos, neg) { return Math.round(Math.abs(v)) + "° " + (v >= 0 ? pos : neg); };
    out.textContent = "Spine " + tilt(you[0], "forward", "back") + " (expert " + tilt(them[0], "forward", "back") + "), " +
      tilt(you[1], "to the left", "to the right") + " (expert " + tilt(them[1], "to the left", "to the right") + ") · " +
      "shoulders turned " + Math.round(Math.abs(you[2])) + "° (expert " + Math.round(Math.abs(them[2])) + "°) · " +
      "hips turned " + Math.round(Math.abs(you[3])) + "° (expert " + Math.round(Math.abs(them[3])) + "°), since the first frame";
  }
  function showAngle() {
    showPosture();
    const out = $("angle-readout"), b = angleBend();
    if (!b || outside) { out.textContent = ""; return; }
    const you = angles.performer[frame][b.index], them = angles.expert[frame][b.index];
    const d = you - them;
    const how = Math.abs(d) < 1 ? "as the expert" : Math.round(Math.abs(d)) + "° " + (d > 0 ? "more" : "less") + " bent than the expert";
    out.textContent = "you " + Math.round(you) + "°, the expert " + Math.round(them) + "°: " + how;
  }
  $("angle-joint").addEventListener("change", function () { drawOverlay(); showAngle(); });
  // ---------------------------------------------------------------- drawing
  // Strokes over the paused frame, in shares of the video's width and height, saved with a
  // comment pinned to that frame; a comment's drawing shows whenever its frame is on screen.
  const NOTE_INK = "#f03e3e";
  let drawingOn = false, pending = [], pendingFrame = null, stroke = null, drawnComments = [];
  function strokesAt(t) {
    const out = pendingFrame === t ? pending.slice() : [];
    drawnComments.forEach(function (c) { if (c.frame === t) out.push.apply(out, c.drawing); });
    return out;
  }
  function drawNotes() {
    if (!result) return;
    const ctx = overlay.getContext("2d"), W = overlay.width, H = overlay.height;
    ctx.strokeStyle = NOTE_INK; ctx.lineWidth = Math.max(2, H / 110); ctx.lineCap = "round"; ctx.lineJoin = "round";
    strokesAt(frame + first).forEach(function (s) {
      ctx.beginPath();
      s.forEach(function (q, i) { if (i) ctx.lineTo(q[0] * W, q[1] * H); else ctx.moveTo(q[0] * W, q[1] * H); });
      ctx.stroke();
    });
  }
  function share(ev) {
    const r = overlay.getBoundingClientRect();
    return [Math.min(Math.max((ev.clientX - r.left) / r.width, 0), 1), Math.min(Math.max((ev.clientY - r.top) / r.height, 0), 1)];
  }
  $("draw-toggle").addEventListener("click", function () {
    drawingOn = !drawingOn;
    this.setAttribute("aria-pressed", String(drawingOn));
    this.textContent = drawingOn ? "Stop drawing" : "Draw on the video";
    $("stage-box").classList.toggle("drawing", drawingOn);
    if (drawingOn) video.pause();
  });
  $("draw-clear").addEventListener("click", function () {
    pending = []; pendingFrame = null; this.disabled = true; drawOverlay();
  });
  $("stage-box").addEventListener("pointerdown", function (ev) {
    if (!drawingOn || !result) return;
    ev.preventDefault();
    if (pendingFrame !== frame + first) { pending = []; pendingFrame = frame + first; }  // one frame per drawing
    stroke = [share(ev)];
    pending.push(stroke);
    this.setPointerCapture(ev.pointerId);
  });
  $("stage-box").addEventListener("pointermove", function (ev) {
    if (!stroke) return;
    const q = share(ev), last = stroke[stroke.length - 1];
    if (Math.hypot(q[0] - last[0], q[1] - last[1]) < 0.003) return;
    stroke.push(q);
    drawOverlay();
  });
  $("stage-box").addEventListener("pointerup", function () {
    if (!stroke) return;
    if (stroke.length < 2) pending.pop();  // a tap is not a stroke
    stroke = null;
    $("draw-clear").disabled = !pending.length;
    drawOverlay();
  });
  $("stage-box").addEventListener("click", function (ev) {
    if (drawingOn || !angles || !result || outside) return;
    const r = overlay.getBoundingClientRect();
    const u = (ev.clientX - r.left) * overlay.width / r.width, v = (ev.clientY - r.top) * overlay.height / r.height;
    const p = result.frames[frame].joints_2d;
    let best = -1, dist = overlay.height * 0.06;  // a joint within 6 % of the picture's height
    angles.bends.forEach(function (b, k) {
      const d = Math.hypot(p[b.joint][0] - u, p[b.joint][1] - v);
      if (d < dist) { dist = d; best = k; }
    });
    if (best < 0) return;
    $("angle-joint").value = String(best);
    drawOverlay(); showAngle();
  });

  // ---------------------------------------------------------------- segments
  // How sure a bone's error is: half the width of its range over the candidates the video
  // cannot tell apart (a bend in depth one camera cannot measure gets a wide range).
  function spread(width) {
    return width != null && width >= 1 ? " (± " + Math.round(width / 2) + "°, depth unsure)" : "";
  }
  // Against a reference built from several takes: is the segment a fault, or within the
  // expert's own take-to-take variation?
  function rangeText(s) {
    if (s.within_expert_range == null) return null;
    return coach.el("span", { class: s.within_expert_range ? "seg-within" : "seg-outside",
      text: s.within_expert_range ? "within the expert's range" : "outside the expert's range at " + s.outside_bones.slice(0, 3).join(", ") });
  }
  // A segment card's first lines: its name, score, frames and tempo (final and provisional).
  function segmentHead(s) {
    return [
      coach.el("h3", { text: s.name }),
      coach.el("span", { class: "score", text: deg(s.score != null ? s.score : s.mean_error_deg) }),
      coach.el("span", { class: "muted", text: "frames " + s.performer_start + "–" + s.performer_end }),
      coach.el("span", { text: "Tempo: " + s.tempo_text }),
    ];
  }
  function buildSegments() {
    const box = $("segment-cards");
    box.textContent = "";
    summary.segments.forEach(function (s, i) {
      // A small error where the video disagrees is not a good mark: say so on the card.
      const misfit = s.misfit_frames || 0, where = s.misfit_bones || [];
      const span = s.performer_end - s.performer_start + 1;
      const warn = misfit ? coach.el("span", { class: "seg-misfit", text: "⚠ the video disagrees in " + misfit + " of " + span +
        " frames" + (where.length ? ", mostly at " + where.join(", ") : "") + ": look at them yourself" }) : null;
      const card = coach.el("button", { type: "button", class: "seg-card", "data-index": i,
        "aria-label": s.name + ": mean error " + deg(s.mean_error_deg).slice(0, -1) + " degrees" + (misfit ? ", but the video disagrees in " + misfit + " frames; go to the first of them" : "; go to its first frame") }, segmentHead(s).concat([
        rangeText(s),  // null (skipped) for a reference from one take
        coach.el("ul", {}, s.worst_bones.map(function (wb) { return coach.el("li", { text: wb[0] + ": " + deg(wb[1]) + spread(wb[2]) }); })),
        warn,  // null (skipped) where the video agrees
      ]));
      card.style.borderLeftColor = misfit ? MISFIT : coach.errorColor(s.mean_error_deg);
      // a segment where the video disagrees opens at its first such frame, where there is most to see
      const firstMisfit = misfit ? result.frames.findIndex(function (f) {
        return f.t >= s.performer_start && f.t <= s.performer_end && (f.flags || []).indexOf("image_misfit") >= 0;
      }) : -1;
      card.addEventListener("click", function () { video.pause(); seek(firstMisfit >= 0 ? firstMisfit : s.performer_start - first); });
      box.append(card);
    });
    const pin = $("comment-pin");
    summary.segments.forEach(function (s, i) { pin.append(coach.el("option", { value: "segment:" + i, text: "segment: " + s.name })); });
    if (review) {
      const tb = document.querySelector("#segment-table tbody");
      summary.segments.forEach(function (s) {
        const tr = coach.el("tr", {}, [
          coach.el("th", { scope: "row", text: s.name }),
          coach.el("td", { text: s.performer_start + "–" + s.performer_end }),
          coach.el("td", { text: s.reference_start + "–" + s.reference_end }),
          coach.el("td", { text: s.tempo_text }),
          coach.el("td", { text: s.mean_error_deg.toFixed(1) + "°" }),
          coach.el("td", { text: s.worst_bones.map(function (wb) { return wb[0] + " " + deg(wb[1]); }).join(", ") }),
          coach.el("td", { text: s.misfit_frames ? s.misfit_frames + " frames" + ((s.misfit_bones || []).length ? " (" + s.misfit_bones.join(", ") + ")" : "") : "–" }),
        ]);
        tb.append(tr);
      });
    }
  }
  // Key positions: the moments between the reference's segments ("start of downswing"),
  // one button each, to step through a motion the way a coach does.
  function buildKeyPositions() {
    const box = $("key-positions");
    box.replaceChildren(coach.el("span", { class: "muted", text: "Key positions:" }));
    (summary.key_positions || []).forEach(function (k) {
      box.append(coach.el("button", { type: "button", class: "small key", "data-frame": k.frame,
        text: capital(k.name),
        onclick: function () { video.pause(); seek(k.frame - first); } }));
    });
    box.hidden = !(summary.key_positions || []).length;
  }
  function markSegment() {
    if (!summary) return;
    document.querySelectorAll("#segment-cards .seg-card").forEach(function (c) {
      const s = summary.segments[+c.dataset.index];
      c.classList.toggle("current", frame + first >= s.performer_start && frame + first <= s.performer_end);
    });
  }

  // ---------------------------------------------------------------- comments
  async function loadComments() {
    const items = (await coach.api(base + "/comments?limit=100")).items;
    drawnComments = items.filter(function (c) { return c.drawing && c.frame != null; });
    drawOverlay();
    const ul = $("comments");
    ul.textContent = "";
    if (!items.length) ul.append(coach.el("li", { class: "muted", text: "No comments yet." }));
    items.forEach(function (c) {
      let pin;
      if (c.frame != null) pin = coach.el("button", { type: "button", class: "link pin", text: "frame " + c.frame + (c.drawing ? " ✎ drawing" : ""), onclick: function () { video.pause(); seek(c.frame - first); } });
      else if (c.segment != null && summary.segments[c.segment]) pin = coach.el("button", { type: "button", class: "link pin", text: summary.segments[c.segment].name, onclick: function () { video.pause(); seek(summary.segments[c.segment].performer_start - first); } });
      else pin = coach.el("span", { class: "pin", text: "general" });
      const del = coach.el("button", { type: "button", class: "link", text: "Delete", "aria-label": "Delete comment", onclick: async function () {
        await coach.api(base + "/comments/" + c.id, { method: "DELETE" }); loadComments(); } });
      ul.append(coach.el("li", { class: "comment" }, [pin, coach.el("span", { class: "body", text: c.body }),
        coach.el("span", { class: "meta", text: c.author + ", " + c.created_at.slice(0, 16).replace("T", " ") }), del]));
    });
  }
  $("comment-form").addEventListener("submit", async function (ev) {
    ev.preventDefault();
    const body = $("comment-body").value.trim();
    if (!body) return;
    const pin = $("comment-pin").value;
    const data = { body: body };
    if (pin === "frame") data.frame = frame + first;
    else if (pin.startsWith("segment:")) data.segment = +pin.split(":")[1];
    if (pending.length) { data.drawing = pending; data.frame = pendingFrame; delete data.segment; }  // on the frame drawn over
    const button = this.querySelector("button[type=submit]");
    button.disabled = true;
    try {
      await coach.api(base + "/comments", { method: "POST", json: data });
      $("comment-body").value = "";
      pending = []; pendingFrame = null; $("draw-clear").disabled = true;
      await loadComments();
    } finally { button.disabled = false; }
  });

  // ---------------------------------------------------------------- 3D frame at phone width
  // Below 576 px viser 1.1 lays its controls out as a bottom sheet that opens over the scene
  // (its client's BottomPanel starts expanded; main_panel.minimize() does not reach it).
  // Narrower than VISER_MIN_PX, the frame keeps that width and is scaled down to fit, so the
  // scene keeps the desktop layout, its panel minimised; touches are scaled with it.
  const VISER_MIN_PX = 580;  // mantine's xs breakpoint, 36em = 576 px, and a little more
  function fitFrame(iframe) {
    iframe.style.width = ""; iframe.style.height = ""; iframe.style.transform = ""; iframe.style.margin = "";
    const avail = iframe.parentElement.clientWidth - parseFloat(getComputedStyle(iframe.parentElement).paddingLeft) * 2;
    if (!(avail > 0) || avail >= VISER_MIN_PX) { delete iframe.dataset.scale; return; }
    const k = avail / VISER_MIN_PX, h = iframe.getBoundingClientRect().height;
    iframe.style.width = VISER_MIN_PX + "px"; iframe.style.height = (h / k) + "px";
    iframe.style.transformOrigin = "0 0"; iframe.style.transform = "scale(" + k + ")";
    iframe.style.margin = "0 " + (avail - VISER_MIN_PX) + "px " + (h - h / k) + "px 0";
    iframe.dataset.scale = k.toFixed(3);
  }
  function fitFrames() { ["viewer3d", "live-viewer3d"].forEach(function (id) { fitFrame($(id)); }); }
  window.addEventListener("resize", fitFrames);

  // ---------------------------------------------------------------- 3D view
  async function start3d() {
    try {
      const v = await coach.api(base + "/viewer", { method: "POST" });
      const frameEl = $("viewer3d");
      frameEl.src = v.url + TAB + "/";
      frameEl.hidden = false;
      fitFrame(frameEl);
      $("viewer-status").textContent = "3D view: drag to orbit, scroll to zoom. It follows the timeline.";
      viewerReady = true;
      sync3d();
    } catch (e) {
      $("viewer-status").textContent = e.message;
      $("fallback3d").hidden = false;
      draw3dFallback();
    }
  }
  let syncTimer = null, synced = -1;
  function sync3d() {
    if (!viewerReady) { draw3dFallback(); return; }
    if (syncTimer) return;
    syncTimer = setTimeout(function () {
      syncTimer = null;
      if (synced === frame) return;
      synced = frame;
      coach.api(base + "/viewer/frame", { method: "POST", json: { frame: frame, tab: TAB } }).catch(function () {});
    }, 120);
  }
  function draw3dFallback() {
    const c = $("fallback-canvas");
    if ($("fallback3d").hidden || !result) return;
    const ctx = c.getContext("2d");
    ctx.clearRect(0, 0, c.width, c.height);
    const j = result.frames[frame].joints_3d, e = result.frames[frame].bone_errors_deg;
    const hip = j[0], s = c.height / 2.4;
    ctx.lineWidth = 5; ctx.lineCap = "round";
    for (let b = 0; b < 16; b++) {
      const p = j[PARENT[b]], q = j[CHILD[b]];
      ctx.strokeStyle = coach.errorColor(e[b]);
      ctx.beginPath();
      ctx.moveTo(c.width / 2 - (p[0] - hip[0]) * s, c.height * 0.55 - (p[1] - hip[1]) * s);
      ctx.lineTo(c.width / 2 - (q[0] - hip[0]) * s, c.height * 0.55 - (q[1] - hip[1]) * s);
      ctx.stroke();
    }
  }

  // ---------------------------------------------------------------- review mark (coach)
  const toggle = $("review-toggle");
  if (toggle) toggle.addEventListener("click", async function () {
    const on = toggle.dataset.reviewed !== "true";
    try {
      const a = await coach.api(base + "/reviewed", { method: on ? "PUT" : "DELETE" });
      toggle.dataset.reviewed = a.reviewed_at ? "true" : "false";
      toggle.textContent = a.reviewed_at ? "Put back on the to-review list" : "Mark reviewed";
      $("review-state").textContent = a.reviewed_at
        ? "Reviewed on " + a.reviewed_at.slice(0, 10) + "."
        : "Not reviewed yet: it is on the dashboard's to-review list.";
    } catch (e) { $("review-state").textContent = e.message; }
  });

  // ---------------------------------------------------------------- start
  if (root.dataset.status === "done") loadResults();
  else if (root.dataset.status === "queued" || root.dataset.status === "running") follow();
})();
