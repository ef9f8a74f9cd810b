// The after-sale page (docs/console.md, "After-sale"): lane points placed on a photo of a
// car's camera, solved by linecald (POST /api/aftersale, the computation of `linecal
// aftersale`) as they move, the overlay drawn from its answer, the export's files as it
// serves them, and a certificate to print. Uses $, getJson, toLogin and showLogout of app.js.
"use strict";

// Colours of the overlay, as `linecal aftersale --out` draws them (docs/aftersale.md).
const COLOURS = {
  grid: "rgb(0,200,255)", lane: "rgb(0,230,0)", vp: "rgb(255,40,40)",
  horizon: "rgb(255,220,0)", roll: "rgb(255,140,0)", mark: "rgb(255,0,255)",
};
// A press within this many CSS pixels of a point grabs it rather than placing a new one.
const GRAB_PX = 10;
// A press that moves more than this many CSS pixels pans the photo instead of placing a point.
const PAN_PX = 4;
// The magnifier's image pixels per CSS pixel: 8 shows a tenth of a pixel as almost one.
const MAGNIFIER_ZOOM = 8;
// Zoom limits over the fitted view: 1 (the whole photo) to 32 (a pixel 20 CSS px wide on a
// 1100 px view of a 1920 px photo).
const MAX_ZOOM = 32;
const MAX_POINTS = { lane0: 50, lane1: 50, roll: 2, mark: 1 };

// POST `body` (a Blob or a JSON text); the parsed answer, or an Error with the daemon's
// message. A 401 goes to the login page.
async function postJson(path, body, type) {
  const response = await fetch(path, {
    method: "POST", credentials: "same-origin", headers: { "Content-Type": type }, body,
  });
  if (response.status === 401) {
    toLogin();
    throw new Error("login required");
  }
  const answer = await response.json();
  if (!response.ok) throw new Error(answer.error || response.statusText);
  return answer;
}

function numberText(value, digits) {
  return value === null || value === undefined ? "–" : value.toFixed(digits);
}

// A table row of label and numbers, each cell's exact value in data-value (the browser test
// reads them).
function row(table, key, label, values, digits, cls) {
  const tr = table.insertRow();
  tr.dataset.key = key;
  const th = document.createElement("th");
  th.textContent = label;
  tr.appendChild(th);
  for (const v of values) {
    const td = tr.insertCell();
    if (typeof v === "number") {
      td.dataset.value = String(v);
      td.textContent = numberText(v, digits);
    } else {
      td.textContent = v === null || v === undefined ? "–" : String(v);
    }
    if (cls) td.className = cls;
  }
  return tr;
}

class AftersalePage {
  constructor() {
    this.cameras = [];
    this.bitmap = null;
    this.photoName = "";
    this.photoId = "";  // the daemon's id of the uploaded photo, for its bird's-eye view
    this.size = null;  // [width, height] as the daemon read the photo
    this.points = { lane0: [], lane1: [], roll: [], mark: [] };
    this.last = null;  // {key, index} of the point last placed or moved
    this.view = { scale: 1, left: 0, top: 0, fit: 1 };  // CSS px per image px; image edge at the view's corner
    this.pointer = null;  // image point under the pointer
    this.press = null;  // a press in progress: {x, y, grab, panned, view}
    this.answer = null;  // the last solve's answer
    this.answered = "";  // the request it answers
    this.inFlight = false;
    this.pending = false;
    this.exportUrls = [];
    this.solveMs = [];
  }

  // ---- coordinates: image pixel centres at integers (conventions.md), so the pixel (u, v)
  // covers [u - 0.5, u + 0.5) and its left edge is at u - 0.5.
  toImage(x, y) {
    const v = this.view;
    return [x / v.scale + v.left - 0.5, y / v.scale + v.top - 0.5];
  }

  toView(u, v) {
    return [(u + 0.5 - this.view.left) * this.view.scale, (v + 0.5 - this.view.top) * this.view.scale];
  }

  // ---- setup
  async run() {
    await showLogout();
    const answer = await getJson("/api/aftersale/cameras");
    this.cameras = answer.cameras;
    this.maxPhotoBytes = answer.max_photo_bytes;
    const select = $("camera");
    this.cameras.forEach((c, i) => {
      const option = document.createElement("option");
      option.value = String(i);
      option.textContent = c.car_model_id + " · " + c.camera + " (" + c.image_size.join("×") + ")";
      select.appendChild(option);
    });
    select.addEventListener("change", () => this.chooseCamera());
    this.chooseCamera();
    $("photo").addEventListener("change", () => this.loadPhoto());
    for (const id of ["camera-height", "longitudinal-offset", "lateral-offset", "measured-distance",
      "tolerance", "roll-deg"]) {
      $(id).addEventListener("input", () => this.solve());
    }
    $("vin").addEventListener("input", () => this.fillCertificate());
    $("undo").addEventListener("click", () => this.removeLast());
    $("clear").addEventListener("click", () => {
      this.points = { lane0: [], lane1: [], roll: [], mark: [] };
      this.last = null;
      this.changed();
    });
    $("fit").addEventListener("click", () => this.fit());
    $("print").addEventListener("click", () => window.print());
    this.listen();
    window.addEventListener("resize", () => this.fit());
    document.body.dataset.ready = "true";
  }

  camera() {
    return this.cameras[Number($("camera").value)];
  }

  chooseCamera() {
    const c = this.camera();
    if (!c) return;
    $("camera-height").value = c.input.camera_height_m;
    $("longitudinal-offset").value = c.input.longitudinal_offset_m;
    $("lateral-offset").value = c.input.lateral_offset_m;
    this.checkSize();
    this.solve();
  }

  // The photo must be of the camera's resolution: its intrinsics hold for that size only.
  checkSize() {
    const c = this.camera();
    if (!this.size || !c) return true;
    if (this.size[0] === c.image_size[0] && this.size[1] === c.image_size[1]) return true;
    this.showMessage("The photo is " + this.size.join("×") + " pixels, but " + c.camera +
      "'s intrinsics are for " + c.image_size.join("×") + ": choose its camera or a photo of it.");
    return false;
  }

  showMessage(text) {
    $("message").textContent = text;
  }

  async loadPhoto() {
    const file = $("photo").files[0];
    if (!file) return;
    this.showMessage("");
    delete document.body.dataset.photo;
    if (file.size > this.maxPhotoBytes) {
      this.showMessage("Photo refused: " + file.name + " is " + (file.size / 1048576).toFixed(1) +
        " MiB, linecald takes at most " + (this.maxPhotoBytes / 1048576).toFixed(0) + " MiB.");
      return;
    }
    try {
      // The daemon reads it as `linecal aftersale` does (and refuses what it cannot read);
      // the page draws its own decode, of the same size.
      this.size = null;
      this.photoId = "";
      const info = await postJson("/api/aftersale/photo", file, file.type || "application/octet-stream");
      const bitmap = await createImageBitmap(file, { imageOrientation: "none" });
      if (bitmap.width !== info.width || bitmap.height !== info.height) {
        throw new Error("the browser reads the photo as " + bitmap.width + "×" + bitmap.height +
          " and linecald as " + info.width + "×" + info.height);
      }
      this.bitmap = bitmap;
      this.size = [info.width, info.height];
      this.photoName = file.name;
      this.photoId = info.photo_id;
    } catch (error) {
      this.showMessage("Photo refused: " + error.message);
      return;
    }
    this.fit();
    document.body.dataset.photo = this.size.join("x");
    if (this.checkSize()) this.solve();
  }

  // The whole photo in the view's width, at whole CSS pixels (so that a pointer's position
  // maps to the image exactly as the browser test computes it).
  fit() {
    if (!this.bitmap) return;
    const canvas = $("view");
    const width = Math.max(200, Math.floor(canvas.parentElement.clientWidth));
    const height = Math.round(width * this.size[1] / this.size[0]);
    canvas.style.width = width + "px";
    canvas.style.height = height + "px";
    const dpr = window.devicePixelRatio || 1;
    canvas.width = Math.round(width * dpr);
    canvas.height = Math.round(height * dpr);
    const fitScale = width / this.size[0];
    this.view = { scale: fitScale, left: 0, top: 0, fit: fitScale, width, height };
    this.draw();
  }

  // ---- pointer and keys
  listen() {
    const canvas = $("view");
    canvas.addEventListener("pointerdown", (e) => this.onDown(e));
    canvas.addEventListener("pointermove", (e) => this.onMove(e));
    canvas.addEventListener("pointerup", (e) => this.onUp(e));
    canvas.addEventListener("pointerleave", () => { this.pointer = null; this.drawMagnifier(); });
    canvas.addEventListener("wheel", (e) => this.onWheel(e), { passive: false });
    canvas.addEventListener("contextmenu", (e) => e.preventDefault());
    canvas.addEventListener("keydown", (e) => this.onKey(e));
  }

  offset(e) {
    const r = $("view").getBoundingClientRect();
    return [e.clientX - r.left, e.clientY - r.top];
  }

  // The point within GRAB_PX of view position (x, y), nearest first.
  pointAt(x, y) {
    let best = null;
    for (const [key, list] of Object.entries(this.points)) {
      list.forEach((p, index) => {
        const [px, py] = this.toView(p[0], p[1]);
        const d = Math.hypot(px - x, py - y);
        if (d <= GRAB_PX && (!best || d < best.d)) best = { key, index, d };
      });
    }
    return best;
  }

  onDown(e) {
    if (!this.bitmap || e.button !== 0) return;
    $("view").focus();
    $("view").setPointerCapture(e.pointerId);
    const [x, y] = this.offset(e);
    const grab = this.pointAt(x, y);
    this.press = { x, y, grab, panned: false, view: { ...this.view } };
    if (grab) this.last = { key: grab.key, index: grab.index };
  }

  onMove(e) {
    if (!this.bitmap) return;
    const [x, y] = this.offset(e);
    this.pointer = this.toImage(x, y);
    const p = this.press;
    if (p && p.grab) {
      this.points[p.grab.key][p.grab.index] = this.pointer;
      this.changed();
      return;
    }
    if (p && (p.panned || Math.hypot(x - p.x, y - p.y) > PAN_PX)) {
      p.panned = true;
      this.view.left = p.view.left - (x - p.x) / this.view.scale;
      this.view.top = p.view.top - (y - p.y) / this.view.scale;
      this.draw();
      return;
    }
    $("pointer").textContent = "u " + this.pointer[0].toFixed(1) + " · v " + this.pointer[1].toFixed(1) + " px";
    this.drawMagnifier();
  }

  onUp(e) {
    const p = this.press;
    this.press = null;
    if (!p || p.grab || p.panned) return;
    const tool = document.querySelector("input[name=tool]:checked").value;
    const list = this.points[tool];
    if (list.length >= MAX_POINTS[tool]) {
      this.showMessage("The " + (tool === "roll" ? "roll line has its two ends" : "marked point is placed") +
        ": drag it, or remove it first.");
      return;
    }
    const [x, y] = this.offset(e);
    list.push(this.toImage(x, y));
    this.last = { key: tool, index: list.length - 1 };
    this.changed();
  }

  onWheel(e) {
    if (!this.bitmap) return;
    e.preventDefault();
    const [x, y] = this.offset(e);
    const [u, v] = this.toImage(x, y);
    const factor = e.deltaY < 0 ? 1.25 : 0.8;
    const scale = Math.min(this.view.fit * MAX_ZOOM, Math.max(this.view.fit, this.view.scale * factor));
    // The image point under the pointer stays under it.
    this.view.scale = scale;
    this.view.left = u + 0.5 - x / scale;
    this.view.top = v + 0.5 - y / scale;
    if (scale === this.view.fit) {
      this.view.left = 0;
      this.view.top = 0;
    }
    this.draw();
  }

  onKey(e) {
    const steps = { ArrowLeft: [-1, 0], ArrowRight: [1, 0], ArrowUp: [0, -1], ArrowDown: [0, 1] };
    if (!this.last || !steps[e.key]) return;
    e.preventDefault();
    const step = e.shiftKey ? 1 : 0.1;
    const p = this.points[this.last.key][this.last.index];
    if (!p) return;
    this.points[this.last.key][this.last.index] = [p[0] + steps[e.key][0] * step, p[1] + steps[e.key][1] * step];
    this.changed();
  }

  removeLast() {
    if (!this.last) return;
    this.points[this.last.key].splice(this.last.index, 1);
    this.last = null;
    this.changed();
  }

  changed() {
    document.body.dataset.points = JSON.stringify(this.points);
    this.draw();
    this.solve();
  }

  // ---- solving: one request in flight, the newest points sent when it returns
  request() {
    const c = this.camera();
    const p = this.points;
    if (!c || !this.size || p.lane0.length < 2 || p.lane1.length < 2) return null;
    const input = { ...c.input };
    input.camera_height_m = Number($("camera-height").value);
    input.longitudinal_offset_m = Number($("longitudinal-offset").value);
    input.lateral_offset_m = Number($("lateral-offset").value);
    input.tolerance_percent = Number($("tolerance").value);
    input.lanes = [p.lane0, p.lane1];
    if (p.roll.length === 2) {
      input.roll_line = p.roll;
    } else {
      input.roll_deg = Number($("roll-deg").value);
    }
    const distance = $("measured-distance").value;
    if (p.mark.length === 1 && distance !== "") {
      input.marked_point = { uv_px: p.mark[0], measured_distance_m: Number(distance) };
    }
    // With the photo's id the daemon keeps this solve for the photo's bird's-eye view.
    return { image_size: this.size, input, photo_id: this.photoId };
  }

  async solve() {
    if (this.inFlight) {
      this.pending = true;
      return;
    }
    const request = this.request();
    if (!request || !this.checkSize()) {
      this.answer = null;
      this.answered = "";
      this.showResult();
      return;
    }
    const text = JSON.stringify(request);
    if (text === this.answered) return;
    this.inFlight = true;
    const started = performance.now();
    try {
      this.answer = await postJson("/api/aftersale", text, "application/json");
      this.showMessage("");
      delete document.body.dataset.refused;
    } catch (error) {
      this.answer = null;
      this.showMessage("Refused: " + error.message);
      document.body.dataset.refused = text;
    }
    this.answered = text;
    this.inFlight = false;
    this.showResult();
    // From sending the points to the overlay drawn, in milliseconds (the browser test reports
    // them: docs/console.md, "The after-sale page").
    this.solveMs.push(performance.now() - started);
    document.body.dataset.solveMs = JSON.stringify(this.solveMs);
    if (this.pending) {
      this.pending = false;
      this.solve();
    }
  }

  // ---- drawing
  drawScene(ctx, scale, left, top, width, height) {
    ctx.save();
    ctx.fillStyle = "#222";
    ctx.fillRect(0, 0, width, height);
    ctx.imageSmoothingEnabled = scale < 2;
    ctx.drawImage(this.bitmap, -left * scale, -top * scale, this.size[0] * scale, this.size[1] * scale);
    const at = (p) => [(p[0] + 0.5 - left) * scale, (p[1] + 0.5 - top) * scale];
    const polyline = (points, colour, lineWidth) => {
      ctx.strokeStyle = colour;
      ctx.lineWidth = lineWidth;
      ctx.beginPath();
      let open = false;
      for (const p of points) {
        if (!p) {
          open = false;
          continue;
        }
        const [x, y] = at(p);
        if (open) ctx.lineTo(x, y); else ctx.moveTo(x, y);
        open = true;
      }
      ctx.stroke();
    };
    const cross = (p, size, colour) => {
      const [x, y] = at(p);
      ctx.strokeStyle = colour;
      ctx.lineWidth = 2;
      ctx.beginPath();
      ctx.moveTo(x - size, y);
      ctx.lineTo(x + size, y);
      ctx.moveTo(x, y - size);
      ctx.lineTo(x, y + size);
      ctx.stroke();
    };
    const o = this.answer && this.answer.overlay;
    if (o) {
      for (const line of o.ground_grid) polyline(line, COLOURS.grid, 1);
      polyline(o.horizon, COLOURS.horizon, 1.5);
      for (const line of o.lane_lines) polyline(line, COLOURS.lane, 2);
      if (o.vanishing_point) cross(o.vanishing_point, 12, COLOURS.vp);
    }
    if (this.points.roll.length === 2) polyline(this.points.roll, COLOURS.roll, 2);
    for (const p of [...this.points.lane0, ...this.points.lane1]) cross(p, 7, COLOURS.lane);
    for (const p of this.points.roll) cross(p, 7, COLOURS.roll);
    for (const p of this.points.mark) cross(p, 10, COLOURS.mark);
    ctx.restore();
  }

  draw() {
    if (!this.bitmap) return;
    const canvas = $("view");
    const ctx = canvas.getContext("2d");
    const dpr = canvas.width / this.view.width;
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    this.drawScene(ctx, this.view.scale, this.view.left, this.view.top, this.view.width, this.view.height);
    const v = this.view;
    document.body.dataset.view = JSON.stringify({ scale: v.scale, left: v.left, top: v.top, fit: v.fit });
    this.drawMagnifier();
  }

  // The pixels around the pointer (or the point being dragged) at MAGNIFIER_ZOOM, with a
  // cross-hair at the exact image point.
  drawMagnifier() {
    const canvas = $("magnifier");
    const ctx = canvas.getContext("2d");
    if (!this.bitmap || !this.pointer) {
      ctx.clearRect(0, 0, canvas.width, canvas.height);
      return;
    }
    const [u, v] = this.pointer;
    const half = canvas.width / 2 / MAGNIFIER_ZOOM;
    this.drawScene(ctx, MAGNIFIER_ZOOM, u + 0.5 - half, v + 0.5 - half, canvas.width, canvas.height);
    ctx.strokeStyle = "rgba(255,255,255,0.8)";
    ctx.lineWidth = 1;
    ctx.beginPath();
    ctx.moveTo(canvas.width / 2, 0);
    ctx.lineTo(canvas.width / 2, canvas.height);
    ctx.moveTo(0, canvas.height / 2);
    ctx.lineTo(canvas.width, canvas.height / 2);
    ctx.stroke();
  }

  // ---- result, export, certificate
  showResult() {
    this.draw();
    const a = this.answer;
    this.showBirdsEye();
    $("result").hidden = !a;
    if (!a) {
      delete document.body.dataset.solved;
      return;
    }
    const r = a.result;
    const result = $("result-table");
    result.replaceChildren();
    const head = result.createTHead().insertRow();
    for (const title of ["", "yaw / u", "pitch / v", "roll"]) {
      const th = document.createElement("th");
      th.textContent = title;
      head.appendChild(th);
    }
    row(result, "ypr_deg", "mounting (°)", r.ypr_deg, 3);
    row(result, "vanishing_point_px", "vanishing point (px)", r.vanishing_point_px, 2);
    row(result, "xyz_m", "position (m)", r.T_car_camera.xyz_m, 3);
    row(result, "roll_source", "roll from", [r.roll_source === "roll_line" ? "the roll line" : "assumed"]);
    const checks = $("checks-table");
    checks.replaceChildren();
    row(checks, "lane_fit_rms_px", "lane fit RMS (px)", r.lane_fit_rms_px, 3);
    row(checks, "vanishing_point_residual_px", "vanishing point residual (px)", [r.vanishing_point_residual_px], 3);
    if (r.distance_check) {
      const c = r.distance_check;
      row(checks, "distance_check", "distance: computed, measured (m), error (%)",
        [c.computed_distance_m, c.measured_distance_m, c.error_percent], 3);
      const verdict = row(checks, "verdict", "distance check (tolerance " + c.tolerance_percent + " %)",
        [c.verdict.toUpperCase()], 0, c.verdict);
      verdict.dataset.verdict = c.verdict;
    }
    for (const f of r.flat_formula) {
      row(checks, "flat_formula", "flat formula at " + f.distance_m + " m reads (m)", [f.flat_formula_m], 3);
    }
    this.makeDownloads();
    this.fillCertificate();
    document.body.dataset.solved = this.answered;
  }

  // The daemon's bird's-eye picture of the photo through the latest solve (a new path for each
  // solve); hidden without a result. body[data-birdseye] is the path once its image is shown.
  showBirdsEye() {
    const img = $("birdseye");
    const path = this.answer && this.answer.birdseye;
    $("birdseye-figure").hidden = !path;
    if (!path) {
      img.removeAttribute("src");
      delete document.body.dataset.birdseye;
      return;
    }
    if (img.getAttribute("src") === path) return;
    img.onload = () => { if (img.getAttribute("src") === path) document.body.dataset.birdseye = path; };
    img.onerror = () => this.showMessage("The bird's-eye view did not load: upload the photo again.");
    img.src = path;
  }

  makeDownloads() {
    for (const url of this.exportUrls) URL.revokeObjectURL(url);
    this.exportUrls = [];
    const links = $("export-links");
    links.replaceChildren();
    for (const f of this.answer.export) {
      const url = URL.createObjectURL(new Blob([f.text], { type: "application/json" }));
      this.exportUrls.push(url);
      const a = document.createElement("a");
      a.href = url;
      a.download = f.file;
      a.textContent = f.file;
      a.className = "export";
      links.append(a, " ");
    }
    // The input the command takes for the same result: the request's, with the photo's name.
    const input = { ...JSON.parse(this.answered).input, image: this.photoName };
    const url = URL.createObjectURL(new Blob([JSON.stringify(input, null, 2) + "\n"], { type: "application/json" }));
    this.exportUrls.push(url);
    $("input-link").href = url;
    $("input-link").download = "aftersale.json";
  }

  fillCertificate() {
    const a = this.answer;
    const c = this.camera();
    if (!a || !c) return;
    const r = a.result;
    const k = c.input.intrinsics;
    $("cert-vin").textContent = $("vin").value || "–";
    $("cert-date").textContent = new Date().toISOString().slice(0, 10);
    $("cert-car").textContent = c.car_model_id;
    $("cert-camera").textContent = c.camera + " (" + r.image_size.join("×") + " px, " + k.model + ")";
    $("cert-intrinsics").textContent = "fx " + k.fx + ", fy " + k.fy + ", cx " + k.cx + ", cy " + k.cy +
      " px; distortion " + k.distortion.join(", ");
    $("cert-position").textContent = "x " + r.T_car_camera.xyz_m[0] + ", y " + r.T_car_camera.xyz_m[1] +
      ", z (height) " + r.T_car_camera.xyz_m[2];
    const result = $("cert-result");
    result.replaceChildren();
    row(result, "ypr_deg", "yaw, pitch, roll (°)", r.ypr_deg, 3);
    row(result, "vanishing_point_px", "vanishing point (px)", r.vanishing_point_px, 2);
    row(result, "roll_source", "roll from", [r.roll_source === "roll_line" ? "the roll line" : "assumed"]);
    const checks = $("cert-checks");
    checks.replaceChildren();
    row(checks, "lane_fit_rms_px", "lane fit RMS (px)", r.lane_fit_rms_px, 3);
    if (r.distance_check) {
      const d = r.distance_check;
      row(checks, "distance_check", "distance check: computed, measured (m), error (%)",
        [d.computed_distance_m, d.measured_distance_m, d.error_percent], 3);
      row(checks, "verdict", "verdict (tolerance " + d.tolerance_percent + " %)", [d.verdict.toUpperCase()], 0, d.verdict);
    } else {
      row(checks, "verdict", "distance check", ["not made (no marked point)"]);
    }
    // The annotated photo, as the screen shows it fitted.
    const canvas = $("cert-image");
    canvas.height = Math.round(canvas.width * this.size[1] / this.size[0]);
    const scale = canvas.width / this.size[0];
    this.drawScene(canvas.getContext("2d"), scale, 0, 0, canvas.width, canvas.height);
  }
}

document.addEventListener("DOMContentLoaded", () => {
  if (document.body.dataset.page !== "aftersale") return;
  new AftersalePage().run().catch((error) => {
    if (error.message !== "login required") $("message").textContent = error.message;
  });
});
