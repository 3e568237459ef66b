// My analyses (performer): tick two attempts of one reference to compare them; delete one.
"use strict";
(function () {
  const root = document.getElementById("my-analyses");
  if (!root) return;
  const err = document.getElementById("list-error");
  const compare = document.getElementById("compare-two");
  function ticked() { return Array.from(root.querySelectorAll("input.pick:checked")).map(function (c) { return c.closest("tr"); }); }
  function update() {
    const rows = ticked();
    const same = rows.length === 2 && rows[0].dataset.reference === rows[1].dataset.reference;
    compare.disabled = !same;
    let msg = "";
    if (rows.length > 2) msg = "Tick two attempts, not more.";
    else if (rows.length === 2 && !same) msg = "These two attempts follow different references; pick two of the same one.";
    err.textContent = msg;
    err.hidden = !msg;
  }
  root.addEventListener("change", function (ev) { if (ev.target.classList.contains("pick")) update(); });
  compare.addEventListener("click", function () {
    const rows = ticked();  // the table is newest first: A (before) is the older one
    location.href = "/performers/" + root.dataset.performer + "/compare?a=" + rows[1].dataset.id + "&b=" + rows[0].dataset.id;
  });
  root.addEventListener("click", async function (ev) {
    if (!ev.target.classList.contains("delete")) return;
    const row = ev.target.closest("tr");
    if (!confirm("Delete this attempt, its video and its results? This cannot be undone.")) return;
    try {
      await coach.api("/api/v1/analyses/" + row.dataset.id, { method: "DELETE" });
      row.remove();
      update();
    } catch (e) { err.textContent = e.message; err.hidden = false; }
  });
})();
