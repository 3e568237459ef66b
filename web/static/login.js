"use strict";
(function () {
  const form = document.getElementById("login-form");
  const err = document.getElementById("login-error");
  form.addEventListener("submit", async function (ev) {
    ev.preventDefault();
    err.hidden = true;
    try {
      await coach.api("/api/v1/session", { method: "POST", json: {
        email: form.email.value.trim(), password: form.password.value } });
      location.href = form.dataset.next || "/";
    } catch (e) {
      err.textContent = e.message;
      err.hidden = false;
      form.password.focus();
    }
  });
})();
