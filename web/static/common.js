// Shared helpers: JSON fetch with the API's error shape, sign out, colours.
"use strict";
window.coach = (function () {
  async function api(path, opts) {
    opts = opts || {};
    const headers = Object.assign({ Accept: "application/json" }, opts.headers || {});
    if (opts.json !== undefined) {
      headers["Content-Type"] = "application/json";
      opts.body = JSON.stringify(opts.json);
    }
    const r = await fetch(path, Object.assign({ credentials: "same-origin" }, opts, { headers }));
    if (r.status === 204) return null;
    let data = null;
    try { data = await r.json(); } catch (e) { data = null; }
    if (!r.ok) {
      const msg = data && data.error ? data.error.message : "request failed (" + r.status + ")";
      const err = new Error(msg);
      err.status = r.status;
      throw err;
    }
    return data;
  }
  // Same ramp as engine.report.error_colors: green (0 deg) -> yellow -> red (>= 45 deg).
  const RED_AT = 45;
  function errorColor(deg) {
    const x = Math.min(Math.max((deg || 0) / RED_AT, 0), 1);
    const r = Math.min(2 * x, 1), g = Math.min(2 * (1 - x), 1);
    return "rgb(" + Math.round((r * 0.9 + 0.05) * 255) + "," + Math.round((g * 0.9 + 0.05) * 255) + ",13)";
  }
  function el(tag, attrs, children) {
    const e = document.createElement(tag);
    for (const k in attrs || {}) {
      if (k === "text") e.textContent = attrs[k];
      else if (k.startsWith("on")) e.addEventListener(k.slice(2), attrs[k]);
      else e.setAttribute(k, attrs[k]);
    }
    (children || []).forEach(function (c) { if (c) e.append(c); });
    return e;
  }
  // The coach's word for each bone (engine.body.skeleton.BONE_LABELS, one table for every
  // page): by index in the result's bone order, or by "parent->child" / child-joint id.
  const words = JSON.parse(document.body.dataset.boneWords || '{"ids": [], "labels": []}');
  function boneLabel(id) {
    if (typeof id === "number") return words.labels[id];
    let i = words.ids.indexOf(id);
    if (i < 0) i = words.ids.findIndex(function (b) { return b.split("->")[1] === id; });
    return i >= 0 ? words.labels[i] : id;
  }
  const out = document.getElementById("sign-out");
  if (out) out.addEventListener("click", async function () {
    await fetch("/api/v1/session", { method: "DELETE", credentials: "same-origin" });
    location.href = "/login";
  });
  return { api: api, errorColor: errorColor, el: el, RED_AT: RED_AT, boneLabel: boneLabel, BONE_IDS: words.ids };
})();
