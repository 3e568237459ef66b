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

  // Segment boundaries on a plot of the expert's hand speed: drag a boundary (or focus it and
  // use the arrow keys, Shift for 10 frames), add one in the longest segment, remove the
  // selected one, or go back to the boundaries detected in the motion (API motion.json).
  const SVGNS = "http://www.w3.org/2000/svg";
  function svg(tag, attrs) {
    const e = document.createElementNS(SVGNS, tag);
    Object.keys(attrs || {}).forEach(function (k) { e.setAttribute(k, attrs[k]); });
    return e;
  }
  function lines(input) { return input.value.split("\n").map(function (v) { return v.trim(); }).filter(Boolean); }
  function boundaryEditor(r, segInput, keyInput) {
    const W = 600, H = 110, T = 8, B = 18;
    const state = { starts: (r.derived.segments || []).slice(0, -1), end: (r.derived.segments || []).slice(-1)[0], changed: false, reset: false, selected: -1, curve: null };
    const plot = svg("svg", { viewBox: "0 0 " + W + " " + H, class: "boundary-plot", role: "group", "aria-label": "Segment boundaries of " + r.name + " over the expert's hand speed" });
    const text = coach.el("p", { class: "muted boundary-text", "aria-live": "polite" });
    const add = coach.el("button", { type: "button", text: "Add a boundary" });
    const remove = coach.el("button", { type: "button", text: "Remove the selected boundary", disabled: "" });
    const detected = coach.el("button", { type: "button", text: "Use the detected boundaries" });
    const frames = function () { return state.curve ? state.curve.frames : (state.end || 0) + 1; };
    const x = function (f) { return W * f / Math.max(frames() - 1, 1); };
    function fitNames() {  // as many names as segments: keep the coach's, name the new ones
      const names = lines(segInput);
      const n = state.starts.length;
      while (names.length < n) names.push("segment " + (names.length + 1));
      segInput.value = names.slice(0, n).join("\n");
    }
    function draw() {
      plot.textContent = "";
      if (state.curve) {
        // the scale ignores the fastest 1 % of points, so one jerk does not flatten the rest
        const c = state.curve, v = c.speed_m_per_frame;
        const top = v.slice().sort(function (a, b) { return a - b; })[Math.floor(0.99 * (v.length - 1))] || 1;
        const pts = v.map(function (s, i) { return x(i * c.step).toFixed(1) + "," + (T + (H - T - B) * (1 - Math.min(s / top, 1))).toFixed(1); });
        plot.append(svg("polyline", { points: pts.join(" "), fill: "none", stroke: "#8792a2", "stroke-width": 1.2 }));
      }
      const names = lines(segInput);
      state.starts.forEach(function (f, i) {
        const next = i + 1 < state.starts.length ? state.starts[i + 1] : state.end;
        const label = svg("text", { x: (x(f) + x(next)) / 2, y: H - 4, "text-anchor": "middle", "font-size": 11, fill: "#5c6675" });
        label.textContent = names[i] || "segment " + (i + 1);
        plot.append(label);
        if (i === 0) return;  // the motion's start is not a boundary
        const g = svg("g", { class: "boundary" + (i === state.selected ? " selected" : ""), tabindex: 0, role: "slider",
          "aria-label": "Start of " + (names[i] || "segment " + (i + 1)), "aria-valuenow": f, "aria-valuemin": state.starts[i - 1] + 1, "aria-valuemax": next - 1, "data-index": i });
        g.append(svg("rect", { x: x(f) - 6, y: 0, width: 12, height: H - B, fill: "transparent" }),
          svg("line", { x1: x(f), x2: x(f), y1: 0, y2: H - B, stroke: i === state.selected ? "#3b5bdb" : "#c92a2a", "stroke-width": 2 }));
        plot.append(g);
      });
      text.textContent = "Segments start at frames " + state.starts.join(", ") + " (of " + frames() + ")" + (state.changed ? "; not saved yet." : ".");
      remove.disabled = state.selected < 1;
    }
    function move(i, f) {
      const lo = state.starts[i - 1] + 1, hi = (i + 1 < state.starts.length ? state.starts[i + 1] : state.end) - 1;
      state.starts[i] = Math.max(lo, Math.min(hi, Math.round(f)));
      state.changed = true; state.reset = false; state.selected = i;
      draw();
    }
    let dragging = -1;
    plot.addEventListener("pointerdown", function (ev) {
      const g = ev.target.closest && ev.target.closest(".boundary");
      if (!g) return;
      dragging = +g.dataset.index; state.selected = dragging;
      plot.setPointerCapture(ev.pointerId);
      draw();
    });
    plot.addEventListener("pointermove", function (ev) {
      if (dragging < 0) return;
      const pt = plot.createSVGPoint();  // the pointer in the plot's own units (viewBox)
      pt.x = ev.clientX; pt.y = ev.clientY;
      move(dragging, pt.matrixTransform(plot.getScreenCTM().inverse()).x / W * (frames() - 1));
    });
    plot.addEventListener("pointerup", function () {
      const i = dragging;
      dragging = -1;
      if (i > 0) { const g = plot.querySelector('.boundary[data-index="' + i + '"]'); if (g) g.focus(); }
    });
    plot.addEventListener("keydown", function (ev) {
      const g = ev.target.closest && ev.target.closest(".boundary");
      if (!g || ["ArrowLeft", "ArrowRight"].indexOf(ev.key) < 0) return;
      ev.preventDefault();
      const i = +g.dataset.index;
      move(i, state.starts[i] + (ev.key === "ArrowRight" ? 1 : -1) * (ev.shiftKey ? 10 : 1));
      plot.querySelector('.boundary[data-index="' + i + '"]').focus();
    });
    add.addEventListener("click", function () {
      const ends = state.starts.slice(1).concat([state.end]);
      let best = 0;
      ends.forEach(function (e, i) { if (e - state.starts[i] > ends[best] - state.starts[best]) best = i; });
      if (ends[best] - state.starts[best] < 2) return;
      state.starts.splice(best + 1, 0, Math.round((state.starts[best] + ends[best]) / 2));
      state.changed = true; state.reset = false; state.selected = best + 1;
      const keys = lines(keyInput);  // the coach's key positions follow their boundaries
      if (keys.length) { keys.splice(best + 1, 0, "key position " + (best + 2)); keyInput.value = keys.join("\n"); }
      fitNames(); draw();
    });
    remove.addEventListener("click", function () {
      if (state.selected < 1) return;
      const keys = lines(keyInput);
      if (keys.length) { keys.splice(state.selected, 1); keyInput.value = keys.join("\n"); }
      state.starts.splice(state.selected, 1);
      state.changed = true; state.reset = false; state.selected = -1;
      fitNames(); draw();
    });
    detected.addEventListener("click", function () {
      state.reset = true; state.changed = true; state.selected = -1;
      segInput.value = ""; keyInput.value = "";  // their number is the motion's: name them again after saving
      text.textContent = "The boundaries found in the motion are used once you save; name their segments again then.";
    });
    segInput.addEventListener("input", draw);
    coach.api("/api/v1/references/" + r.id + "/motion.json").then(function (c) { state.curve = c; draw(); }).catch(function () { draw(); });
    draw();
    return {
      el: coach.el("div", { class: "boundary-editor" }, [
        coach.el("p", { text: "Segment boundaries (drag a red line, or focus it and use the arrow keys):" }),
        plot, text, coach.el("div", { class: "row" }, [add, remove, detected])]),
      // for PUT /domain: null keeps the stored boundaries, [] goes back to the detected ones
      segments: function () { return !state.changed ? null : (state.reset ? [] : state.starts.slice()); },
    };
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
    const keyInput = coach.el("textarea", { id: id + "-keys", rows: 3 });
    keyInput.value = (dom.key_position_names || []).join("\n");
    const bounds = boundaryEditor(r, segInput, keyInput);
    const f = coach.el("form", { class: "stack", "aria-label": "Edit " + r.name }, [
      coach.el("label", { for: id + "-name", text: "Name" }), nameInput,
      bounds.el,
      coach.el("label", { for: id + "-segs", text: "Segment names (" + (r.segment_names.length ? r.segment_names.length + " segments, " : "") + "one a line, in order)" }), segInput,
      coach.el("label", { for: id + "-keys", text: "Key positions (optional: the moment at each segment's start, then the last one's end, one a line; e.g. address, top, impact, finish)" }), keyInput,
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
        const segments = bounds.segments();
        const body = {
          name: nameInput.value.trim() || null,
          segment_names: lines(segInput), key_position_names: lines(keyInput),
          bone_weights: weights, tolerances_deg: tols, default_tolerance_deg: +dflt.value || 0 };
        if (segments !== null) body.segments = segments;
        const saved = await coach.api("/api/v1/references/" + r.id + "/domain", { method: "PUT", json: body });
        if (segments !== null) {  // new boundaries: redraw the card (strip, plot) from the stored ones
          const fresh = card(saved);
          const strip = fresh.querySelector("img");
          if (strip) strip.src = saved.strip + (saved.strip.indexOf("?") < 0 ? "?" : "&") + "s=" + saved.derived.segments.join("-");
          fresh.querySelector("p.saved").textContent = "Saved.";
          f.closest(".ref-card").replaceWith(fresh);
          return;
        }
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
