// Progress over time: a performer's attempts (mean error, a trend line per reference) and two
// attempts side by side (segments, error curves over the reference's frames, videos).
"use strict";
(function () {
  const root = document.getElementById("compare");
  const pid = root.dataset.performer;
  const $ = function (s) { return document.getElementById(s); };
  const SVGNS = "http://www.w3.org/2000/svg";
  const COLOUR = { a: "#868e96", b: "#1971c2" };
  function svg(tag, attrs, text) {
    const e = document.createElementNS(SVGNS, tag);
    for (const k in attrs) e.setAttribute(k, attrs[k]);
    if (text != null) e.textContent = text;
    return e;
  }
  const fmt = function (v, d) { return v == null ? "–" : v.toFixed(d == null ? 1 : d); };
  const day = function (iso) { return iso.slice(0, 16).replace("T", " "); };
  let history = [];

  // ---------------------------------------------------------------- attempts and trend
  function trend(items) {
    const pts = items.filter(function (a) { return a.mean_error_deg != null; });
    const W = 320, H = 70, P = 6;
    const s = svg("svg", { viewBox: "0 0 " + W + " " + H, class: "trend", role: "img",
      "aria-label": "mean error of " + pts.length + " attempts, oldest to newest" });
    if (pts.length < 1) return s;
    const top = Math.max.apply(null, pts.map(function (a) { return a.mean_error_deg; })) * 1.15 || 1;
    const x = function (i) { return P + (W - 2 * P) * (pts.length > 1 ? i / (pts.length - 1) : 0.5); };
    const y = function (v) { return P + (H - 2 * P) * (1 - v / top); };
    s.append(svg("polyline", { points: pts.map(function (a, i) { return x(i) + "," + y(a.mean_error_deg); }).join(" "),
      fill: "none", stroke: "#c92a2a", "stroke-width": 2 }));
    pts.forEach(function (a, i) {
      const c = svg("circle", { cx: x(i), cy: y(a.mean_error_deg), r: 4, fill: "#c92a2a" });
      c.append(svg("title", {}, day(a.created_at) + ": " + fmt(a.mean_error_deg) + "°"));
      s.append(c);
    });
    return s;
  }
  function renderHistory(sel) {
    const box = $("history");
    box.textContent = "";
    const byRef = {};
    history.forEach(function (a) { (byRef[a.reference_id] = byRef[a.reference_id] || []).push(a); });
    if (!history.length) box.append(coach.el("p", { class: "muted", text: "No analyses yet." }));
    Object.keys(byRef).forEach(function (rid) {
      const items = byRef[rid];
      const rows = items.map(function (a) {
        const done = a.status === "done";
        function pick(side) {
          const r = coach.el("input", { type: "radio", name: "pick-" + side, value: a.id, "data-ref": rid,
            "aria-label": side.toUpperCase() + ": attempt of " + day(a.created_at) });
          r.checked = sel[side] === a.id;
          r.disabled = !done;
          r.addEventListener("change", onPick);
          return coach.el("td", {}, [r]);
        }
        return coach.el("tr", { "data-id": a.id }, [
          coach.el("td", {}, [coach.el("a", { href: a.url, text: day(a.created_at) })]),
          coach.el("td", { text: done ? fmt(a.mean_error_deg) + "°" : a.status }),
          pick("a"), pick("b"),
        ]);
      });
      box.append(coach.el("div", { class: "history-ref" }, [
        coach.el("h3", { text: items[0].reference }),
        trend(items),
        coach.el("table", { class: "list history-table" }, [
          coach.el("thead", {}, [coach.el("tr", {}, ["Uploaded (UTC)", "Mean error", "A", "B"].map(function (h) { return coach.el("th", { scope: "col", text: h }); }))]),
          coach.el("tbody", {}, rows),
        ]),
      ]));
    });
  }
  function onPick() {
    const a = document.querySelector("input[name=pick-a]:checked");
    const b = document.querySelector("input[name=pick-b]:checked");
    if (!a || !b || a.value === b.value) return;
    if (a.dataset.ref !== b.dataset.ref) { showError("Pick two attempts of the same reference."); return; }
    const q = "?a=" + encodeURIComponent(a.value) + "&b=" + encodeURIComponent(b.value);
    window.history.replaceState(null, "", location.pathname + q);
    load(a.value, b.value);
  }
  function showError(msg) { $("cmp-error").textContent = msg; $("cmp-error").hidden = !msg; }
  function defaults() {
    // The two latest finished attempts of the reference used last.
    const done = history.filter(function (a) { return a.status === "done"; });
    if (!done.length) return {};
    const rid = done[done.length - 1].reference_id;
    const same = done.filter(function (a) { return a.reference_id === rid; });
    return same.length >= 2 ? { a: same[same.length - 2].id, b: same[same.length - 1].id } : {};
  }

  // ---------------------------------------------------------------- A vs B
  function badge(change, deltaText) {
    const cls = { better: "better", worse: "worse", same: "same" }[change] || "same";
    const word = { better: "better", worse: "worse", same: "about the same" }[change] || "–";
    return coach.el("span", { class: "change " + cls, text: word + (deltaText ? " (" + deltaText + ")" : "") });
  }
  const signed = function (v) { return v == null ? "" : (v > 0 ? "+" : "") + v.toFixed(1) + "°"; };
  function renderComparison(d) {
    $("comparison").hidden = false;
    const sum = $("cmp-summary");
    sum.textContent = "";
    sum.append(document.createTextNode("Mean error " + fmt(d.mean.a) + "° (A, " + day(d.a.created_at) + ") → " +
      fmt(d.mean.b) + "° (B, " + day(d.b.created_at) + "): "), badge(d.mean.change, signed(d.mean.change_deg)));
    const tb = document.querySelector("#cmp-table tbody");
    tb.textContent = "";
    d.segments.forEach(function (s) {
      tb.append(coach.el("tr", { "data-change": s.error_change || "" }, [
        coach.el("th", { scope: "row", text: s.name }),
        coach.el("td", { text: s.a ? fmt(s.a.mean_error_deg) + "°" : "–" }),
        coach.el("td", { text: s.b ? fmt(s.b.mean_error_deg) + "°" : "–" }),
        coach.el("td", {}, [badge(s.error_change, signed(s.error_change_deg))]),
        coach.el("td", { text: s.a ? s.a.tempo_text : "–" }),
        coach.el("td", { text: s.b ? s.b.tempo_text : "–" }),
        coach.el("td", {}, [badge(s.tempo_change)]),
      ]));
    });
    plot(d);
    $("video-a").src = d.a.video; $("video-b").src = d.b.video;
    $("cap-a").textContent = "A: " + day(d.a.created_at);
    $("cap-b").textContent = "B: " + day(d.b.created_at);
    root.dataset.ready = "true";
  }
  function plot(d) {
    const W = 1000, H = 220, L = 40, R = 10, T = 10, B = 28;
    const lo = d.reference_frames[0], hi = Math.max(d.reference_frames[1], lo + 1);
    // The axis fits the data (small errors still show which attempt and frames differ), in
    // the analysis page's whole-degree steps.
    let most = 0;
    ["a", "b"].forEach(function (k) { d.curves[k].forEach(function (p) { most = Math.max(most, p[1]); }); });
    const top = [2, 4, 8, 12, 20, 40, 60, 80, 120, 180].find(function (v) { return v >= most * 1.1; }) || 180;
    const x = function (f) { return L + (W - L - R) * (f - lo) / (hi - lo); };
    const y = function (v) { return T + (H - T - B) * (1 - v / top); };
    const s = svg("svg", { viewBox: "0 0 " + W + " " + H, preserveAspectRatio: "none", id: "cmp-plot-svg",
      role: "img", "aria-label": "posture error of A and B over the reference's frames" });
    d.segments.forEach(function (seg, i) {
      const side = seg.a || seg.b;
      if (!side) return;
      s.append(svg("rect", { x: x(side.reference_start), y: T, width: Math.max(x(side.reference_end) - x(side.reference_start), 1),
        height: H - T - B, fill: i % 2 ? "#eef2fb" : "#f8f9fc" }));
      s.append(svg("text", { x: x(side.reference_start) + 4, y: T + 12, "font-size": 11, fill: "#5c6675" }, seg.name));
    });
    for (let v = 0; v <= top; v += top / 4) {
      s.append(svg("line", { x1: L, x2: W - R, y1: y(v), y2: y(v), stroke: "#e3e6ec" }));
      s.append(svg("text", { x: 4, y: y(v) + 4, "font-size": 11, fill: "#5c6675" }, (top < 4 ? v.toFixed(1) : Math.round(v)) + "°"));
    }
    ["a", "b"].forEach(function (k) {
      const pl = svg("polyline", { class: "curve-" + k, fill: "none", stroke: COLOUR[k], "stroke-width": k === "b" ? 3 : 2,
        "vector-effect": "non-scaling-stroke",
        points: d.curves[k].map(function (p) { return x(p[0]).toFixed(1) + "," + y(p[1]).toFixed(1); }).join(" ") });
      pl.append(svg("title", {}, k.toUpperCase()));
      s.append(pl);
    });
    s.append(svg("text", { x: L, y: H - 8, "font-size": 11, fill: "#5c6675" }, "reference frame " + lo));
    s.append(svg("text", { x: W - R - 130, y: H - 8, "font-size": 11, fill: "#5c6675" }, "reference frame " + hi));
    let lx = L + 260;
    [["A (before)", COLOUR.a], ["B (after)", COLOUR.b]].forEach(function (it) {
      s.append(svg("rect", { x: lx, y: H - 14, width: 16, height: 4, fill: it[1] }));
      s.append(svg("text", { x: lx + 20, y: H - 8, "font-size": 11, fill: "#333" }, it[0]));
      lx += 110;
    });
    $("cmp-plot").textContent = "";
    $("cmp-plot").append(s);
  }
  $("play-both").addEventListener("click", function () {
    [$("video-a"), $("video-b")].forEach(function (v) { v.currentTime = 0; v.play().catch(function () {}); });
  });

  async function load(a, b) {
    showError("");
    try { renderComparison(await coach.api("/api/v1/performers/" + pid + "/compare?a=" + encodeURIComponent(a) + "&b=" + encodeURIComponent(b))); }
    catch (e) { $("comparison").hidden = true; showError(e.message); }
  }
  (async function start() {
    try {
      history = (await coach.api("/api/v1/performers/" + pid + "/history")).analyses;
    } catch (e) { $("history-error").textContent = e.message; $("history-error").hidden = false; return; }
    let sel = { a: root.dataset.a, b: root.dataset.b };
    if (!sel.a || !sel.b) sel = defaults();
    renderHistory(sel);
    if (sel.a && sel.b) load(sel.a, sel.b);
  })();
})();
