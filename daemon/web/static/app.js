// The station console's pages (docs/console.md): plain browser JavaScript over the JSON API
// and the event stream of daemon/web/web_server.h. No build step; no network beyond linecald.
"use strict";

// What the operator does on a fail, by reason code (the words of station/solvers and the
// core's reasons); the first matching prefix or suffix wins.
const HINTS = [
  [/^acquisition_failed/, "The sensor sent no data: check its cable and power, then repeat the cycle."],
  [/^board_not_found/, "The board was not seen: check that it stands in place, uncovered and lit, and that the sensor's view is clear; repeat."],
  [/^(yaw|pitch|roll|x|y|z|position)_out_of_tolerance/, "The sensor is mounted outside tolerance: adjust its bracket, then repeat the cycle."],
  [/_out_of_tolerance/, "The sensor is mounted outside tolerance: adjust its bracket, then repeat the cycle."],
  [/^(residual|uncertainty)_too_high/, "The measurement is unsure: check that the car stands still and the boards are clean; repeat."],
  [/deadline_exceeded/, "The station took too long: repeat; if it happens again call the station engineer."],
];
const DEFAULT_HINT = "Repeat the cycle; if it fails again call the station engineer.";

// The step a sensor has reached, by event type.
const STEPS = {
  sensor_progress: "acquiring",
  sensor_acquired: "acquired",
  board_found: "board found",
  sensor_solved: "solved",
  sensor_verdict: "done",
  sensor_error: "error",
};

function $(id) { return document.getElementById(id); }

function hintFor(reason) {
  for (const [pattern, hint] of HINTS) {
    if (pattern.test(reason)) return hint;
  }
  return DEFAULT_HINT;
}

function toLogin() {
  const next = location.pathname + location.search;
  location.assign("/login.html?next=" + encodeURIComponent(next));
}

// GET a JSON API path; a 401 (no or expired session) goes to the login page.
async function getJson(path) {
  const response = await fetch(path, { credentials: "same-origin" });
  if (response.status === 401) {
    toLogin();
    throw new Error("login required");
  }
  const body = await response.json();
  if (!response.ok) throw new Error(body.error || response.statusText);
  return body;
}

function setVerdict(element, word, text) {
  element.textContent = text || word || "–";
  element.className = "verdict-badge " + (word || "pending");
}

async function showLogout() {
  const session = await getJson("/api/session");
  const link = $("logout");
  if (!link || !session.login_required) return;
  link.hidden = false;
  link.addEventListener("click", async (event) => {
    event.preventDefault();
    await fetch("/api/logout", { method: "POST", credentials: "same-origin" });
    toLogin();
  });
}

// ---- login.html
function loginPage() {
  const params = new URLSearchParams(location.search);
  // Only a path of this site: "//host" or "https://..." would send the operator elsewhere.
  let next = params.get("next") || "/";
  if (!next.startsWith("/") || next.startsWith("//")) next = "/";
  $("login-form").addEventListener("submit", async (event) => {
    event.preventDefault();
    $("login-message").textContent = "";
    const response = await fetch("/api/login", {
      method: "POST",
      credentials: "same-origin",
      headers: { "Content-Type": "application/json" },
      body: JSON.stringify({ token: $("token").value }),
    });
    if (response.ok) {
      location.assign(next);
      return;
    }
    const body = await response.json();
    $("login-message").textContent =
      response.status === 401 ? "Wrong token." : (body.error || response.statusText);
  });
}

// ---- index.html: the live station
class LivePage {
  constructor() {
    this.cycleId = "";
    this.rows = new Map();  // sensor name -> its table row
  }

  row(name) {
    let tr = this.rows.get(name);
    if (tr) return tr;
    tr = document.createElement("tr");
    tr.dataset.sensor = name;
    for (const cls of ["name", "step", "verdict", "reason"]) {
      const td = document.createElement("td");
      td.className = cls;
      tr.appendChild(td);
    }
    tr.querySelector(".name").textContent = name;
    tr.querySelector(".step").textContent = "waiting";
    tr.querySelector(".verdict").textContent = "…";
    tr.querySelector(".verdict").classList.add("pending");
    $("sensors").appendChild(tr);
    this.rows.set(name, tr);
    return tr;
  }

  // A new cycle: the car, and a row per sensor of its model in the model's order.
  async startCycle(cycle) {
    this.cycleId = cycle.cycle_id;
    this.rows.clear();
    $("sensors").replaceChildren();
    $("hint").textContent = "";
    $("vin").textContent = cycle.vin;
    $("model").textContent = cycle.car_model_id;
    document.body.dataset.cycle = cycle.cycle_id;
    delete document.body.dataset.ended;
    setVerdict($("cycle-verdict"), "", "running");
    const link = $("cycle-link");
    link.href = "/cycle.html?id=" + encodeURIComponent(cycle.cycle_id);
    link.hidden = false;
    try {
      const car = await getJson("/api/cars/" + encodeURIComponent(cycle.car_model_id));
      if (this.cycleId !== cycle.cycle_id) return;
      for (const s of car.sensors) $("sensors").appendChild(this.row(s.name));
    } catch (error) {
      // A car model no longer configured: rows come with the events instead.
      $("connection").textContent = "car model: " + error.message;
    }
  }

  onEvent(e) {
    if (e.cycle_id !== this.cycleId) return;
    if (e.type === "cycle_ended") {
      setVerdict($("cycle-verdict"), e.verdict, e.verdict || e.detail || "ended");
      const failed = [...this.rows.values()].filter((tr) => tr.dataset.verdict && tr.dataset.verdict !== "pass");
      $("hint").textContent = failed.length ? hintFor(failed[0].dataset.reason || "") : "";
      document.body.dataset.ended = e.cycle_id;
      return;
    }
    if (!e.sensor) return;
    const tr = this.row(e.sensor);
    tr.querySelector(".step").textContent =
      e.type === "sensor_progress" && e.detail ? e.detail : (STEPS[e.type] || e.type);
    if (e.type === "sensor_verdict" || e.type === "sensor_error") {
      const verdict = e.verdict || "error";
      tr.dataset.verdict = verdict;
      tr.dataset.reason = e.detail;
      // How long after the daemon stored the verdict it was shown (docs/console.md, "Bars";
      // the browser test reads it): same machine, same clock, in milliseconds.
      tr.dataset.shownAfterMs = String(Date.now() - e.time_ns / 1e6);
      const cell = tr.querySelector(".verdict");
      cell.textContent = verdict.toUpperCase();
      cell.className = "verdict " + verdict;
      tr.querySelector(".reason").textContent = verdict === "pass" ? "" : e.detail;
    }
  }

  async run() {
    const status = await getJson("/api/status");
    $("station").textContent = "linecal · " + status.station_id;
    await showLogout();
    const events = new EventSource("/api/events");
    // Events are applied in order, each after the cycle's car model is in place.
    let queue = Promise.resolve();
    events.addEventListener("open", () => { $("connection").textContent = "live"; });
    events.addEventListener("cycle", (m) => {
      const cycle = JSON.parse(m.data);
      queue = queue.then(() => this.startCycle(cycle));
    });
    events.addEventListener("cycle_event", (m) => {
      const e = JSON.parse(m.data);
      queue = queue.then(() => this.onEvent(e));
    });
    events.addEventListener("error", async () => {
      $("connection").textContent = "reconnecting…";
      // The stream breaks when the session ends too: then log in again.
      const session = await getJson("/api/session");
      if (session.login_required && !session.logged_in) {
        events.close();
        toLogin();
      }
    });
  }
}

// ---- cycle.html: one cycle's numbers
const AXES = [
  ["yaw_deg", "yaw", "°", 3],
  ["pitch_deg", "pitch", "°", 3],
  ["roll_deg", "roll", "°", 3],
  ["x_m", "x", "m", 4],
  ["y_m", "y", "m", 4],
  ["z_m", "z", "m", 4],
];

// A table cell showing `value` with `digits` decimals; the exact number in data-value.
function numberCell(value, digits, cls) {
  const td = document.createElement("td");
  if (value === undefined || value === null) {
    td.textContent = "–";
    return td;
  }
  td.dataset.value = String(value);
  td.textContent = value.toFixed(digits);
  if (cls) td.className = cls;
  return td;
}

function sensorSection(s, model) {
  const section = document.createElement("section");
  section.className = "sensor";
  section.dataset.sensor = s.name;
  const h2 = document.createElement("h2");
  const verdict = document.createElement("span");
  verdict.className = "verdict " + (s.verdict || "pending");
  verdict.textContent = (s.verdict || "none").toUpperCase();
  h2.append(s.name + " (" + s.kind + ") ", verdict);
  section.appendChild(h2);
  if (s.verdict !== "pass") {
    const p = document.createElement("p");
    p.className = "reason";
    p.textContent = [s.reason, s.message].filter((x) => x).join(": ");
    section.appendChild(p);
  }
  const table = document.createElement("table");
  table.className = "numbers";
  const head = table.createTHead().insertRow();
  for (const title of ["", "found", "nominal", "deviation", "tolerance ±", "σ"]) {
    const th = document.createElement("th");
    th.textContent = title;
    head.appendChild(th);
  }
  const body = table.createTBody();
  for (const [key, label, unit, digits] of AXES) {
    const tr = body.insertRow();
    tr.dataset.axis = key;
    const name = document.createElement("td");
    name.className = "name";
    name.textContent = label + " (" + unit + ")";
    tr.appendChild(name);
    const deviation = s.deviation[key];
    const tolerance = model ? model.tolerance[key] : undefined;
    const out = tolerance !== undefined && Math.abs(deviation) > tolerance;
    tr.appendChild(numberCell(s.mounting[key], digits, "found"));
    tr.appendChild(numberCell(model ? model.nominal[key] : undefined, digits, "nominal"));
    tr.appendChild(numberCell(deviation, digits, out ? "deviation out" : "deviation"));
    tr.appendChild(numberCell(tolerance, digits, "tolerance"));
    tr.appendChild(numberCell(s.uncertainty[key], digits, "sigma"));
  }
  section.appendChild(table);
  const fit = document.createElement("p");
  fit.className = "fit";
  const unit = { camera: "px", lidar: "m", radar: "°" }[s.kind] || "";
  const residual = document.createElement("span");
  residual.className = "residual";
  residual.dataset.value = String(s.residual_rms);
  residual.textContent = s.residual_rms.toPrecision(4) + " " + unit;
  fit.append("residual RMS ", residual, " · features used " + s.features_used);
  section.appendChild(fit);
  return section;
}

async function cyclePage() {
  const id = new URLSearchParams(location.search).get("id") || "";
  $("cycle-id").textContent = id;
  let cycle;
  try {
    cycle = await getJson("/api/cycles/" + encodeURIComponent(id));
  } catch (error) {
    $("cycle-message").textContent = error.message;
    return;
  }
  $("vin").textContent = cycle.vin;
  $("model").textContent = cycle.car_model_id;
  setVerdict($("cycle-verdict"), cycle.verdict, cycle.verdict || cycle.state);
  const started = new Date(cycle.started_ns / 1e6);
  const seconds = cycle.ended_ns ? ((cycle.ended_ns - cycle.started_ns) / 1e9).toFixed(2) + " s" : "running";
  $("cycle-times").textContent = "started " + started.toISOString() + " · " + seconds + " · " + cycle.state;
  if (cycle.reason) $("cycle-message").textContent = cycle.reason;
  let models = new Map();
  try {
    const car = await getJson("/api/cars/" + encodeURIComponent(cycle.car_model_id));
    models = new Map(car.sensors.map((s) => [s.name, s]));
  } catch (error) {
    $("cycle-message").textContent += " (car model: " + error.message + ")";
  }
  for (const s of cycle.sensors) $("cycle-sensors").appendChild(sensorSection(s, models.get(s.name)));
  document.body.dataset.loaded = cycle.cycle_id;
}

const PAGES = { login: loginPage, live: () => new LivePage().run(), cycle: cyclePage };
document.addEventListener("DOMContentLoaded", () => {
  const page = PAGES[document.body.dataset.page];
  if (page) {
    Promise.resolve(page()).catch((error) => {
      // Shown on the page; a 401 has already gone to the login page.
      if (error.message !== "login required") document.title = "linecal · " + error.message;
    });
  }
});
