// The cycle page's recorded data (docs/console.md, "Cycle views"): once app.js has shown the
// cycle (body[data-loaded]), the capture's files as download links and, in each sensor's
// section, its view from /api/cycles/ID/views/NAME drawn as SVG: a camera's frame with the
// detected features and the reprojected board over it, a LiDAR's points from above with the
// boards fitted and expected, a radar's detections with the reflectors expected and found.
"use strict";

(function () {
  const SVG = "http://www.w3.org/2000/svg";

  function svg(name, attributes) {
    const element = document.createElementNS(SVG, name);
    for (const [key, value] of Object.entries(attributes || {})) element.setAttribute(key, value);
    return element;
  }

  async function json(path) {
    const response = await fetch(path, { credentials: "same-origin" });
    const body = await response.json();
    if (!response.ok) throw new Error(body.error || response.statusText);
    return body;
  }

  function text(tag, content, cls) {
    const element = document.createElement(tag);
    element.textContent = content;
    if (cls) element.className = cls;
    return element;
  }

  function legend(entries) {
    const p = document.createElement("p");
    p.className = "legend";
    for (const [cls, label] of entries) {
      const key = document.createElement("span");
      key.className = "key " + cls;
      p.append(key, label + "  ");
    }
    return p;
  }

  // A polygon's points attribute from [x, y, ...] points mapped by `at`.
  function points(list, at) {
    return list.map((p) => at(p).join(",")).join(" ");
  }

  // One <path> of round dots, one zero-length segment each: 20,000 points stay one element.
  function dots(list, at, width, cls) {
    const d = list.map((p) => { const [x, y] = at(p); return "M" + x + " " + y + "h0"; }).join("");
    return svg("path", { d: d, class: cls, "stroke-width": width });
  }

  function cameraView(view, cycleId) {
    const figure = document.createElement("figure");
    figure.className = "view camera-view";
    figure.dataset.sensor = view.sensor;
    const frame = document.createElement("div");
    frame.className = "frame";
    const img = document.createElement("img");
    img.alt = view.sensor + " frame " + view.frame;
    img.addEventListener("load", () => { figure.dataset.imageLoaded = String(img.naturalWidth); });
    img.src = "/api/cycles/" + encodeURIComponent(cycleId) + "/capture/" + view.image;
    // Pixel centres are integers, so the image spans [-0.5, W - 0.5] (camera_model.h).
    const overlay = svg("svg", {
      viewBox: [-0.5, -0.5, view.width, view.height].join(" "),
      preserveAspectRatio: "none",
    });
    const r = Math.max(view.width, view.height) / 250;
    let detected = 0;
    for (const board of view.boards) {
      for (const [id, u, v] of board.reprojected) {
        const cross = "M" + (u - r) + " " + v + "h" + 2 * r + "M" + u + " " + (v - r) + "v" + 2 * r;
        overlay.appendChild(svg("path", { d: cross, class: "reprojected", "data-id": id,
                                          "stroke-width": r / 3 }));
      }
      for (const [id, u, v] of board.detected) {
        overlay.appendChild(svg("circle", { cx: u, cy: v, r: r, class: "detected",
                                            "data-board": board.id, "data-id": id,
                                            "stroke-width": r / 3 }));
        ++detected;
      }
    }
    figure.dataset.detected = String(detected);
    frame.append(img, overlay);
    figure.appendChild(frame);
    const boards = view.boards.map((b) => b.id + ": " + (b.found ? "found" : b.partial ? "partial" : "not found " + b.reason)
                                          + ", " + b.detected.length + " features").join(" · ");
    figure.appendChild(legend([["detected", "detected (" + view.detected_features + ")"],
                               ["reprojected", "board at the " + view.mounting + " mounting (" +
                                               view.reprojected_features + ")"]]));
    const caption = text("figcaption", "frame " + (view.frame + 1) + " of " + view.frames + " · " + boards);
    if (view.frames > 1) caption.prepend(frameChoice(view, cycleId, figure), " ");
    figure.appendChild(caption);
    return figure;
  }

  // A camera with several frames: a choice of frame that replaces the figure by that frame's.
  function frameChoice(view, cycleId, figure) {
    const select = document.createElement("select");
    select.className = "frame-choice";
    for (let k = 0; k < view.frames; ++k) {
      const option = text("option", "frame " + (k + 1));
      option.value = String(k);
      option.selected = k === view.frame;
      select.appendChild(option);
    }
    select.addEventListener("change", async () => {
      try {
        const next = await json("/api/cycles/" + encodeURIComponent(cycleId) + "/views/" +
                                encodeURIComponent(view.sensor) + "?frame=" + select.value);
        figure.replaceWith(cameraView(next, cycleId));
      } catch (error) {
        figure.appendChild(text("p", "view: " + error.message, "message"));
      }
    });
    return select;
  }

  // A top view: `at` maps a sensor-frame [x, y] to SVG coordinates (forward up).
  function topView(cls, sensor, box, at) {
    const figure = document.createElement("figure");
    figure.className = "view " + cls;
    figure.dataset.sensor = sensor;
    const [x0, y0] = at([box[0], box[2]]), [x1, y1] = at([box[1], box[3]]);
    let left = Math.min(x0, x1), top = Math.min(y0, y1);
    let width = Math.abs(x1 - x0), height = Math.abs(y1 - y0);
    // Landscape, 4:3 to 3:2, so that a long narrow area (a radar's reflectors ahead) still
    // fits the screen: the short side grows about the centre.
    if (height > width * 0.75) { left -= (height / 0.75 - width) / 2; width = height / 0.75; }
    if (width > height * 1.5) { top -= (width / 1.5 - height) / 2; height = width / 1.5; }
    const plot = svg("svg", { viewBox: [left, top, width, height].join(" "), class: "top" });
    plot.appendChild(svg("rect", { x: left, y: top, width: width, height: height, class: "ground" }));
    const s = Math.max(width, height) / 150;
    // The sensor: a triangle pointing forward.
    plot.appendChild(svg("path", { d: "M0 " + -s + "L" + s / 2 + " " + s / 2 + "L" + -s / 2 + " " + s / 2 + "Z",
                                   class: "sensor-mark" }));
    figure.appendChild(plot);
    return { figure: figure, plot: plot, unit: s };
  }

  function lidarView(view) {
    // LiDAR frame: y forward, x right (the vendor frame), so x stays x and forward goes up.
    const at = (p) => [p[0], -p[1]];
    const { figure, plot, unit } = topView("lidar-view", view.sensor, view.area, at);
    plot.appendChild(dots(view.points, at, unit / 4, "points"));
    for (const board of view.boards) {
      plot.appendChild(svg("polygon", { points: points(board.expected_outline, at), class: "expected",
                                        "stroke-width": unit / 3, "stroke-dasharray": unit + " " + unit / 2 }));
      for (const h of board.expected_holes) {
        const [x, y] = at(h);
        plot.appendChild(svg("circle", { cx: x, cy: y, r: unit / 2, class: "expected-hole",
                                         "stroke-width": unit / 6 }));
      }
      if (!board.found) continue;
      plot.appendChild(svg("polygon", { points: points(board.outline, at), class: "fitted",
                                        "data-board": board.id, "stroke-width": unit / 3 }));
      for (const h of board.holes) {
        const [x, y] = at(h.p);
        plot.appendChild(svg("circle", { cx: x, cy: y, r: unit / 2, class: "hole", "data-id": h.id }));
      }
    }
    figure.dataset.points = String(view.points.length);
    figure.appendChild(legend([["points", view.points.length + " of " + view.points_total + " points"],
                               ["fitted", "board fitted, holes"], ["expected", "board expected (nominal)"]]));
    const boards = view.boards.map((b) => b.id + ": " + (b.found ? "found, " + b.holes.length + " holes" : b.reason));
    figure.appendChild(text("figcaption", "from above, forward up · " + view.frames + " rotations · " +
                                          boards.join(" · ")));
    return figure;
  }

  function radarView(view) {
    // Radar frame: x forward, y left; forward up means SVG x = -y, y = -x.
    const at = (p) => [-p[1], -p[0]];
    const spots = [[0, 0]];
    for (const r of view.reflectors) spots.push(r.expected, ...(r.found ? [r.found] : []));
    const margin = 1.5;
    const box = [Math.min(...spots.map((p) => p[0])) - margin, Math.max(...spots.map((p) => p[0])) + margin,
                 Math.min(...spots.map((p) => p[1])) - margin, Math.max(...spots.map((p) => p[1])) + margin];
    const { figure, plot, unit } = topView("radar-view", view.sensor, box, at);
    plot.appendChild(dots(view.detections, at, unit / 2, "detections"));
    for (const r of view.reflectors) {
      const [ex, ey] = at(r.expected);
      plot.appendChild(svg("circle", { cx: ex, cy: ey, r: unit * 1.5, class: "expected",
                                       "stroke-width": unit / 3, "data-id": r.id }));
      if (r.found) {
        const [fx, fy] = at(r.found);
        plot.appendChild(svg("circle", { cx: fx, cy: fy, r: unit * 0.8, class: "found", "data-id": r.id }));
      }
      if (r.solved) {
        const [sx, sy] = at(r.solved);
        plot.appendChild(svg("path", { d: "M" + (sx - unit) + " " + sy + "h" + 2 * unit + "M" + sx + " " +
                                          (sy - unit) + "v" + 2 * unit, class: "solved", "stroke-width": unit / 3 }));
      }
    }
    figure.appendChild(legend([["detections", view.detections.length + " of " + view.detections_total + " detections"],
                               ["expected", "reflector expected (nominal)"], ["found", "found"],
                               ["solved", "at the solved yaw"]]));
    figure.appendChild(text("figcaption", "from above, forward up · " + view.cycles + " radar cycles · " +
                                          view.reflectors.map((r) => r.id + ": " + r.status).join(" · ")));
    return figure;
  }

  function captureLinks(capture, cycleId) {
    const section = document.createElement("section");
    section.id = "capture";
    section.appendChild(text("h2", "Capture"));
    if (!capture.kept) {
      section.appendChild(text("p", "No capture: " + capture.reason, "muted"));
      return section;
    }
    // The whole capture as one tar archive (daemon/web/capture_archive.h), replayable as is.
    const all = document.createElement("a");
    all.id = "capture-archive";
    all.href = "/api/cycles/" + encodeURIComponent(cycleId) + "/capture.tar";
    all.download = "";
    all.textContent = "Download the whole capture (cycle-" + cycleId + "-capture.tar)";
    const total = capture.files.reduce((n, f) => n + f.bytes, 0);
    const p = document.createElement("p");
    p.append(all, " · " + capture.files.length + " files, " + (total / 1048576).toFixed(1) + " MB");
    section.appendChild(p);
    const list = document.createElement("ul");
    list.className = "files";
    for (const f of capture.files) {
      const a = document.createElement("a");
      a.href = "/api/cycles/" + encodeURIComponent(cycleId) + "/capture/" + f.index;
      a.download = "";
      a.textContent = f.path;
      const li = document.createElement("li");
      li.append(a, " " + (f.bytes / 1024).toFixed(0) + " kB");
      list.appendChild(li);
    }
    section.appendChild(list);
    return section;
  }

  async function showViews(cycleId) {
    const capture = await json("/api/cycles/" + encodeURIComponent(cycleId) + "/capture");
    document.querySelector("main").appendChild(captureLinks(capture, cycleId));
    if (!capture.kept) {
      document.body.dataset.views = "none";
      return;
    }
    const draw = { camera: (v) => cameraView(v, cycleId), lidar: lidarView, radar: radarView };
    const sections = [...document.querySelectorAll("section.sensor")];
    await Promise.all(sections.map(async (section) => {
      try {
        const view = await json("/api/cycles/" + encodeURIComponent(cycleId) + "/views/" +
                                encodeURIComponent(section.dataset.sensor));
        section.appendChild(draw[view.kind](view));
      } catch (error) {
        section.appendChild(text("p", "view: " + error.message, "message"));
      }
    }));
    document.body.dataset.views = cycleId;
  }

  function start() {
    const id = document.body.dataset.loaded;
    if (!id || document.body.dataset.viewsStarted) return false;
    document.body.dataset.viewsStarted = "1";
    showViews(id).catch((error) => { document.body.dataset.views = "error: " + error.message; });
    return true;
  }

  document.addEventListener("DOMContentLoaded", () => {
    if (document.body.dataset.page !== "cycle" || start()) return;
    const observer = new MutationObserver(() => { if (start()) observer.disconnect(); });
    observer.observe(document.body, { attributes: true, attributeFilter: ["data-loaded"] });
  });
})();
