// Invite link: create the performer's account, which signs them in, then go to the upload page.
"use strict";
(function () {
  const form = document.getElementById("join-form");
  const err = document.getElementById("join-error");
  form.addEventListener("submit", async function (ev) {
    ev.preventDefault();
    err.hidden = true;
    const button = form.querySelector("button[type=submit]");
    button.disabled = true;
    try {
      const r = await coach.api("/api/v1/join/" + encodeURIComponent(form.dataset.token), { method: "POST", json: {
        display_name: document.getElementById("join-name").value.trim(),
        email: document.getElementById("join-email").value.trim(),
        password: document.getElementById("join-password").value } });
      location.href = r.url;
    } catch (e) {
      err.textContent = e.message; err.hidden = false; button.disabled = false;
    }
  });
})();
