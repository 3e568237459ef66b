// Dashboard (coach): create a single-use invite link for a new performer.
"use strict";
(function () {
  const form = document.getElementById("invite-form");
  if (!form) return;
  const err = document.getElementById("invite-error");
  const out = document.getElementById("invite-result");
  const link = document.getElementById("invite-link");
  form.addEventListener("submit", async function (ev) {
    ev.preventDefault();
    err.hidden = true;
    try {
      const r = await coach.api("/api/v1/invites", { method: "POST", json: {
        display_name: document.getElementById("invite-name").value.trim(),
        days: +document.getElementById("invite-days").value } });
      link.value = r.url;
      document.getElementById("invite-expires").textContent = r.expires_at.slice(0, 16).replace("T", " ") + " UTC";
      out.hidden = false;
      link.focus(); link.select();
    } catch (e) { err.textContent = e.message; err.hidden = false; }
  });
  document.getElementById("invite-copy").addEventListener("click", async function () {
    link.select();
    try { await navigator.clipboard.writeText(link.value); this.textContent = "Copied"; }
    catch (e) { document.execCommand && document.execCommand("copy"); this.textContent = "Copied"; }
  });
})();
