/* sandbox sweep page: the results table, sortable and filterable; plain JavaScript. */
(function () {
  "use strict";
  const D = JSON.parse(document.getElementById("replay-data").textContent);
  const $ = (id) => document.getElementById(id);
  const header = D.header, rows = D.rows.map((cells, i) => ({ cells, i }));
  const col = (name) => header.indexOf(name);
  const statusCol = col("status"), hitsCol = col("collisions.total"), idCol = col("run_id");
  const numeric = header.map((_, j) => rows.every((r) => r.cells[j] === "" || Number.isFinite(Number(r.cells[j]))));
  let sortBy = -1, ascending = true;

  function esc(text) {
    return String(text).replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" })[c]);
  }

  function build() {
    const statuses = [...new Set(rows.map((r) => r.cells[statusCol]))].sort();
    for (const s of statuses) {
      const o = document.createElement("option"); o.value = s; o.textContent = s; $("status").appendChild(o);
    }
    const tr = document.createElement("tr");
    const replay = document.createElement("th");
    replay.textContent = "replay"; replay.className = "text";
    tr.appendChild(replay);
    header.forEach((name, j) => {
      const th = document.createElement("th");
      th.textContent = name;
      th.className = numeric[j] ? "" : "text";
      th.dataset.col = String(j);
      th.addEventListener("click", () => { ascending = sortBy === j ? !ascending : true; sortBy = j; show(); });
      tr.appendChild(th);
    });
    document.querySelector("#results thead").appendChild(tr);
    for (const id of ["status", "collisions", "kept"]) $(id).addEventListener("change", show);
    $("kept-note").textContent = D.kept
      ? `${D.kept} of ${rows.length} runs link their replay.`
      : "No run links a replay: run the sweep with --keep-runs to keep the run directories.";
  }

  function short(c, j) { // a number shown with 4 significant digits (the cell's title has all)
    if (!numeric[j] || c === "" || !c.includes(".")) return c;
    return String(Number(Number(c).toPrecision(4)));
  }

  function keepRow(r) {
    const status = $("status").value, hits = $("collisions").value;
    if (status && r.cells[statusCol] !== status) return false;
    const n = Number(r.cells[hitsCol]);
    if (hits === "none" && !(r.cells[hitsCol] !== "" && n === 0)) return false;
    if (hits === "some" && !(n > 0)) return false;
    if ($("kept").checked && !D.links[r.cells[idCol]]) return false;
    return true;
  }

  function compare(a, b) {
    if (sortBy < 0) return a.i - b.i;
    const x = a.cells[sortBy], y = b.cells[sortBy];
    let c;
    if (x === "" || y === "") c = (x === "") - (y === "");
    else if (numeric[sortBy]) c = Number(x) - Number(y);
    else c = x < y ? -1 : x > y ? 1 : 0;
    if (!ascending && x !== "" && y !== "") c = -c;
    return c || a.i - b.i;
  }

  function show() {
    const shown = rows.filter(keepRow).sort(compare);
    const body = document.querySelector("#results tbody");
    body.innerHTML = shown.map((r) => {
      const failed = !["ok", ""].includes(r.cells[statusCol]);
      const link = D.links[r.cells[idCol]];
      const cells = r.cells.map((c, j) => `<td class="${numeric[j] ? "" : "text"}" title="${esc(c)}">${esc(short(c, j))}</td>`).join("");
      const replay = link ? `<a href="${esc(link)}">replay</a>` : "";
      return `<tr class="${failed ? "failed" : ""}" data-run="${esc(r.cells[idCol])}"><td class="text">${replay}</td>${cells}</tr>`;
    }).join("");
    document.querySelectorAll("#results th[data-col]").forEach((th, j) => {
      th.classList.toggle("sorted-asc", j === sortBy && ascending);
      th.classList.toggle("sorted-desc", j === sortBy && !ascending);
    });
    $("count").textContent = `${shown.length} of ${rows.length} runs`;
  }

  build();
  show();
  window.sandboxSweep = { rows: () => [...document.querySelectorAll("#results tbody tr")].map((tr) => tr.dataset.run) };
})();
