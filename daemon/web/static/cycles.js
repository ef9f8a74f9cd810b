// The cycles list (docs/console.md, "The cycles list"): the station's cycles newest first from
// GET /api/cycles, filtered by VIN and verdict as ListCycles is, up to 1,000 a page, each
// linked to its cycle page. $ and getJson come from app.js.
"use strict";

// The list's query from the address (?vin=V&verdict=W&limit=N&before=ID) into the form, and
// the API path that lists it.
function cyclesQuery() {
  const wanted = new URLSearchParams(location.search);
  $("vin-filter").value = wanted.get("vin") || "";
  $("verdict-filter").value = wanted.get("verdict") || "";
  const limit = wanted.get("limit");
  if (limit && ![...$("limit").options].some((o) => o.value === limit)) {
    const option = document.createElement("option");
    option.textContent = limit;
    $("limit").appendChild(option);
  }
  if (limit) $("limit").value = limit;
  const query = new URLSearchParams({ limit: $("limit").value });
  for (const key of ["vin", "verdict", "before"]) {
    if (wanted.get(key)) query.set(key, wanted.get(key));
  }
  return query;
}

function cell(tr, text, cls) {
  const td = tr.insertCell();
  td.textContent = text;
  if (cls) td.className = cls;
  return td;
}

// One table row; built detached, so that 1,000 rows cost one layout when appended.
function cycleRow(c) {
  const tr = document.createElement("tr");
  tr.dataset.cycle = c.cycle_id;
  const a = document.createElement("a");
  a.href = "/cycle.html?id=" + encodeURIComponent(c.cycle_id);
  a.textContent = c.cycle_id;
  tr.insertCell().appendChild(a);
  cell(tr, c.vin);
  cell(tr, c.car_model_id);
  cell(tr, new Date(c.started_ns / 1e6).toISOString().replace("T", " ").slice(0, 19));
  cell(tr, c.ended_ns ? ((c.ended_ns - c.started_ns) / 1e9).toFixed(1) + " s" : "");
  cell(tr, c.state);
  cell(tr, c.verdict ? c.verdict.toUpperCase() : "–", "verdict " + (c.verdict || "pending"));
  cell(tr, c.reason, "reason");
  return tr;
}

// The fetch starts when this deferred script runs (the page is parsed by then).
const query = cyclesQuery();
const listed = getJson("/api/cycles?" + query.toString());
listed.catch(() => {});

async function cyclesPage() {
  let page;
  try {
    page = await listed;
  } catch (error) {
    $("cycles-message").textContent = error.message;
    document.body.dataset.loaded = "error";
    return;
  }
  const rows = document.createDocumentFragment();
  for (const c of page.cycles) rows.appendChild(cycleRow(c));
  $("cycles").replaceChildren(rows);
  if (!page.cycles.length) $("cycles-message").textContent = "No cycle matches.";
  if (page.next_before) {
    const older = new URLSearchParams(query);
    older.set("before", page.next_before);
    $("older").href = "/cycles.html?" + older.toString();
    $("older").hidden = false;
  }
  // Read by the browser test: the rows shown and when (ms since the navigation started).
  document.body.dataset.rows = page.cycles.length;
  document.body.dataset.drawnAtMs = performance.now().toFixed(1);
  document.body.dataset.loaded = query.toString();
}

document.addEventListener("DOMContentLoaded", () => {
  cyclesPage().catch((error) => {
    if (error.message !== "login required") document.title = "linecal · " + error.message;
  });
});
