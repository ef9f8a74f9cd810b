// The trends page: per sensor and car model, each deviation axis and the residual of the last
// N cars with tolerance bands and EWMA control limits, the moved-target alarm and the sensors
// that detected each target (docs/console.md, "Trends and station health"). Charts are Debian's
// Chart.js (/vendor/chart.js); getJson and $ come from app.js.
"use strict";

const UNITS = { yaw_deg: "°", pitch_deg: "°", roll_deg: "°", x_m: "m", y_m: "m", z_m: "m", residual_rms: "" };
const charts = [];

// Points as {x: cycle id, y} on a linear axis with parsing off: Chart.js then neither parses
// nor builds 10,000 category labels, which is most of its time on long series.
function points(ids, values) {
  const out = new Array(values.length);
  for (let i = 0; i < values.length; ++i) out[i] = { x: ids[i], y: values[i] };
  return out;
}

// A line's points where it changes: of a run of equal values only the first and the last,
// which draw the same line (straight, or a step) with far fewer points. EWMA control limits
// are constant after a few dozen cars and the per-target counts change rarely: measured, the
// counts chart of 1,000 cycles drew in 11-14 ms instead of 54-83 ms.
function corners(ids, values) {
  const out = [];
  const n = values.length;
  for (let i = 0; i < n; ++i) {
    if (i > 0 && i < n - 1 && values[i] === values[i - 1] && values[i] === values[i + 1]) continue;
    out.push({ x: ids[i], y: values[i] });
  }
  return out;
}

function line(label, data, color, dash) {
  return { label, data, borderColor: color, borderWidth: 1, pointRadius: 0, borderDash: dash || [],
           fill: false };
}

function chartOptions(title) {
  return {
    animation: false, normalized: true, parsing: false, maintainAspectRatio: false,
    // Long series drawn as each pixel column's lowest and highest point (Chart.js's own
    // decimation): 10,000 cars on a 450-pixel chart keep their extremes, at a tenth of the work.
    plugins: { decimation: { enabled: true, algorithm: "min-max" },
               title: { display: Boolean(title), text: title },
               legend: { labels: { filter: (item) => item.text !== "" } } },
    scales: { x: { type: "linear", title: { display: true, text: "cycle" },
                   ticks: { maxTicksLimit: 10, precision: 0 } } },
  };
}

function seriesChart(canvas, series, ids) {
  const ends = ids.length ? [ids[0], ids[ids.length - 1]] : [];
  const flat = (v) => ends.map((x) => ({ x, y: v }));
  const datasets = [
    // Dots filled without an outline: one fill a car instead of a fill and a stroke.
    { label: "result", data: points(ids, series.values), borderColor: "#555", backgroundColor: "#555",
      showLine: false, pointRadius: 1.5, pointBorderWidth: 0 },
    line("EWMA", points(ids, series.ewma), "#1565c0"),
  ];
  if (series.upper.length) {
    datasets.push(line("control limits", corners(ids, series.upper), "#ef6c00", [6, 3]));
    datasets.push(line("", corners(ids, series.lower), "#ef6c00", [6, 3]));
  }
  if (series.tolerance > 0) {
    datasets.push(line("tolerance", flat(series.tolerance), "#b00020", [2, 2]));
    datasets.push(line("", flat(-series.tolerance), "#b00020", [2, 2]));
  }
  const unit = UNITS[series.name];
  return new Chart(canvas, { type: "line", data: { datasets },
                             options: chartOptions(series.name + (unit ? ` (${unit})` : "")) });
}

function showAlarms(alarms) {
  const box = $("alarms");
  box.replaceChildren();
  for (const a of alarms) {
    const div = document.createElement("div");
    div.className = "alarm";
    const shifts = a.sensors.map((s) => `${s.sensor} ${s.shift_sigmas >= 0 ? "+" : ""}${s.shift_sigmas.toFixed(1)} σ`);
    div.textContent = `Target ${a.targets.join(" or ")} (car model ${a.car_model}) has likely moved ` +
      `since cycle ${a.since_cycle_id}: residuals rose together (${shifts.join(", ")}); ` +
      `check and re-survey it before more cars fail.`;
    div.dataset.targets = a.targets.join(",");
    box.appendChild(div);
  }
  $("no-alarm").hidden = alarms.length > 0;
}

function showCounts(counts) {
  const palette = ["#1565c0", "#2e7d32", "#ef6c00", "#6a1b9a", "#00838f", "#c62828", "#4e342e", "#546e7a"];
  const datasets = counts.map((c, i) => ({ ...line(`${c.target} (of ${c.sensors})`,
                                                   corners(c.cycle_ids, c.detected), palette[i % palette.length]),
                                           stepped: true }));
  const options = chartOptions("");
  options.scales.y = { beginAtZero: true, ticks: { stepSize: 1 } };
  charts.push(new Chart($("counts"), { type: "line", data: { datasets }, options }));
}

function trendsPath() {
  return `/api/trends?cycles=${$("cycles").value}&sensor=${encodeURIComponent($("sensor").value)}`;
}

// Draws the trends of the form's sensor and count; `early` is their fetch when already started.
async function load(early) {
  const started = performance.now();
  const sensor = $("sensor").value;
  const body = await (early || getJson(trendsPath()));
  const fetched = performance.now();
  for (const c of charts.splice(0)) c.destroy();
  $("charts").replaceChildren();
  showAlarms(body.alarms);
  for (const t of body.trends) {
    // The residual first: it is what a moved target raises (the mountings barely move).
    const series = [t.series[t.series.length - 1], ...t.series.slice(0, -1)];
    for (const s of series) {
      const holder = document.createElement("div");
      const canvas = document.createElement("canvas");
      canvas.dataset.series = s.name;
      holder.appendChild(canvas);
      $("charts").appendChild(holder);
      charts.push(seriesChart(canvas, s, s.cycle_ids));
    }
  }
  showCounts(body.counts);
  const points = body.trends.reduce((n, t) => n + (t.series[0] ? t.series[0].values.length : 0), 0);
  // Read by the browser test: the cars drawn, how long fetching and drawing took, and when
  // the charts were drawn (ms since the navigation started).
  document.body.dataset.points = points;
  document.body.dataset.fetchMs = (fetched - started).toFixed(1);
  document.body.dataset.drawMs = (performance.now() - fetched).toFixed(1);
  document.body.dataset.drawnAtMs = performance.now().toFixed(1);
  document.body.dataset.loaded = `${sensor}:${$("cycles").value}`;
}

// The form as the address asks (?sensor=S&cycles=N).
function applyAddress(wanted) {
  const cycles = wanted.get("cycles");
  if (cycles && ![...$("cycles").options].some((o) => o.value === cycles)) {
    const option = document.createElement("option");
    option.textContent = cycles;
    $("cycles").appendChild(option);
  }
  if (cycles) $("cycles").value = cycles;
}

// Both fetches start when this script runs, after the page is parsed and before Chart.js has
// run (trends.html loads this script before it): the daemon computes the trends while the
// browser compiles Chart.js, instead of one after the other. The trends need the sensor: when
// the address names none, the first of the status's, so they wait for it.
const wanted = new URLSearchParams(location.search);
applyAddress(wanted);
const early = { status: getJson("/api/status") };
if (wanted.get("sensor")) {
  const option = document.createElement("option");
  option.textContent = wanted.get("sensor");
  $("sensor").appendChild(option);
  early.trends = getJson(trendsPath());
}
// Handled here so that a failure is not reported as unhandled before the page awaits it.
for (const p of Object.values(early)) p.catch(() => {});

// The sensor menu from the station's status, keeping the chosen sensor.
async function fillSensors() {
  const status = await early.status;
  const chosen = $("sensor").value;
  $("sensor").replaceChildren();
  for (const s of status.sensors) {
    const option = document.createElement("option");
    option.textContent = s.name;
    $("sensor").appendChild(option);
  }
  if (chosen) $("sensor").value = chosen;
}

async function trendsPage() {
  // With the sensor in the address the charts need not wait for the menu.
  if (early.trends) {
    await Promise.all([fillSensors(), load(early.trends)]);
  } else {
    await fillSensors();
    await load();
  }
  $("sensor").addEventListener("change", () => load());
  $("cycles").addEventListener("change", () => load());
}

document.addEventListener("DOMContentLoaded", () => {
  trendsPage().catch((error) => {
    if (error.message !== "login required") document.title = "linecal · " + error.message;
  });
});
