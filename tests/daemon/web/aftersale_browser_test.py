#!/usr/bin/python3
"""The after-sale page in a real headless Chromium against a real linecald (docs/console.md,
"After-sale"): a lane scene of `linecal sim lanes` is uploaded as the photo, its lane points,
roll line and marked point are clicked on the page's canvas (Selenium pointer actions at
viewport pixels), one point is dragged and the view zoomed with the wheel; every placed point
must be the image point under the pointer (u = x / scale - 0.5, centre of the top-left pixel
at 0), the page's numbers must equal `linecal aftersale --json` on the same points as doubles,
its three export downloads `linecal aftersale --export`'s files byte for byte, its input
download the command's input; the certificate prints on one page; the browser logs no errors.
Screenshots (aftersale.png, aftersale-certificate.png) go to --screenshots.

Uses console_browser_test.py's daemon and browser helpers. Exit 0 passed, 1 failed, 77
skipped when Chromium, its driver or Selenium is missing.
"""
import base64
import json
import os
import re
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import console_browser_test as console  # noqa: E402  (skips with 77 without Selenium)
from console_browser_test import Failure, check, wait  # noqa: E402
from selenium.webdriver.common.action_chains import ActionChains  # noqa: E402
from selenium.webdriver.common.actions.action_builder import ActionBuilder  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.common.actions.wheel_input import ScrollOrigin  # noqa: E402
from selenium.webdriver.support.ui import Select  # noqa: E402

VIN = "WVWZZZ1KZAW000123"
CAMERA = "front_camera"
# The worked example of docs/aftersale.md, without click noise: the page's clicks are the noise.
SCENE = ["--ypr-deg", "0.8,2.1,-0.6", "--xyz-m", "1.9,0,1.35", "--points-m", "5,10,20,30",
         "--blur", "0.7", "--seed", "3"]


def run(cmd, what, codes=(0,)):
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=console.WAIT_S)
    check(out.returncode in codes, f"{what}: exit {out.returncode}: {out.stderr}")
    return out.stdout, out.returncode


def js(driver, script, *args):
    return driver.execute_script(script, *args)


def view(driver):
    return json.loads(driver.find_element(By.TAG_NAME, "body").get_attribute("data-view"))


def canvas_rect(driver):
    return js(driver, "const r = document.getElementById('view').getBoundingClientRect();"
                      "return [r.left, r.top, r.width, r.height];")


def click_at(driver, x, y):
    """A press and release at viewport pixel (x, y) (integers, as a mouse gives them)."""
    actions = ActionBuilder(driver)
    actions.pointer_action.move_to_location(x, y).pointer_down().pointer_up()
    actions.perform()


def place(driver, rect, scale, point):
    """Clicks the viewport pixel nearest to image point `point` at the fitted view; returns the
    image point that pixel stands for, as the page must compute it."""
    x = round(rect[0] + (point[0] + 0.5) * scale)
    y = round(rect[1] + (point[1] + 0.5) * scale)
    click_at(driver, x, y)
    return [(x - rect[0]) / scale - 0.5, (y - rect[1]) / scale - 0.5], (x, y)


def page_points(driver):
    text = driver.find_element(By.TAG_NAME, "body").get_attribute("data-points")
    return json.loads(text) if text else {}


def solved(driver):
    text = driver.find_element(By.TAG_NAME, "body").get_attribute("data-solved")
    return json.loads(text) if text else None


def wait_solved_with(driver, points, distance):
    """The page's shown result is that of exactly these points and measured distance."""
    def ready(d):
        s = solved(d)
        if not s:
            return False
        i = s["input"]
        return (i["lanes"] == [points["lane0"], points["lane1"]] and i.get("roll_line") == points["roll"]
                and i.get("marked_point", {}).get("uv_px") == points["mark"][0]
                and i["marked_point"]["measured_distance_m"] == distance)
    wait(driver, "the result of the placed points", ready)
    return solved(driver)


def values(driver, table, key):
    row = driver.find_element(By.CSS_SELECTOR, f"#{table} tr[data-key='{key}']")
    return [float(td.get_attribute("data-value")) for td in row.find_elements(By.CSS_SELECTOR, "td[data-value]")]


def compare_with_command(driver, args, work, request, tag):
    """The command on the page's request: its numbers equal the page's, as doubles."""
    input_doc = dict(request["input"], image=os.path.join(work, "scene", f"{CAMERA}.png"))
    path = os.path.join(work, f"input-{tag}.json")
    with open(path, "w") as f:
        json.dump(input_doc, f)
    export = os.path.join(work, f"export-{tag}")
    # Exit 1: done, the distance check failed (docs/aftersale.md).
    text, code = run([args.linecal, "aftersale", "--input", path, "--json", "--export", export,
                      "--out", os.path.join(work, f"out-{tag}")], "linecal aftersale", codes=(0, 1))
    cli = json.loads(text)
    check(code == (1 if cli["distance_check"]["verdict"] == "fail" else 0), f"{tag}: exit {code}")
    shown = {
        ("result-table", "ypr_deg"): cli["ypr_deg"],
        ("result-table", "vanishing_point_px"): cli["vanishing_point_px"],
        ("result-table", "xyz_m"): cli["T_car_camera"]["xyz_m"],
        ("checks-table", "lane_fit_rms_px"): cli["lane_fit_rms_px"],
        ("checks-table", "vanishing_point_residual_px"): [cli["vanishing_point_residual_px"]],
        ("checks-table", "distance_check"): [cli["distance_check"][k] for k in
                                             ("computed_distance_m", "measured_distance_m", "error_percent")],
        ("cert-result", "ypr_deg"): cli["ypr_deg"],
        ("cert-checks", "distance_check"): [cli["distance_check"][k] for k in
                                            ("computed_distance_m", "measured_distance_m", "error_percent")],
    }
    compared = 0
    for (table, key), expected in shown.items():
        got = values(driver, table, key)
        check(got == expected, f"{tag}: {table} {key}: page {got} vs linecal aftersale {expected}")
        compared += len(got)
    verdict = driver.find_element(By.CSS_SELECTOR, "#checks-table tr[data-key='verdict']").get_attribute("data-verdict")
    check(verdict == cli["distance_check"]["verdict"], f"{tag}: verdict {verdict} vs {cli['distance_check']['verdict']}")
    return cli, export, compared


# The bird's-eye picture shown and the command's, decoded by the browser: their sizes and how
# many pixels differ, and by how much at most (any channel).
COMPARE_PICTURES = """
const done = arguments[arguments.length - 1];
const bytes = Uint8Array.from(atob(arguments[0]), (c) => c.charCodeAt(0));
const pixels = (bitmap) => {
  const canvas = new OffscreenCanvas(bitmap.width, bitmap.height);
  const ctx = canvas.getContext("2d");
  ctx.drawImage(bitmap, 0, 0);
  return ctx.getImageData(0, 0, bitmap.width, bitmap.height).data;
};
Promise.all([createImageBitmap(new Blob([bytes], { type: "image/png" })),
             createImageBitmap(document.getElementById("birdseye"))]).then(([expected, shown]) => {
  const a = pixels(expected), b = pixels(shown);
  let differing = 0, worst = 0;
  for (let i = 0; i < a.length && a.length === b.length; i += 4) {
    const d = Math.max(...[0, 1, 2, 3].map((k) => Math.abs(a[i + k] - b[i + k])));
    if (d > 0) differing += 1;
    worst = Math.max(worst, d);
  }
  done({ expected: [expected.width, expected.height], shown: [shown.width, shown.height], differing, worst });
}).catch((e) => done({ error: String(e) }));
"""


def compare_birdseye(driver, url, work, tag):
    """The page's bird's-eye view of the current result is `linecal aftersale --out`'s
    <camera>-birdseye.png for the same points: the daemon's bytes equal the file's, and the
    picture shown equals it pixel for pixel."""
    wait(driver, "the bird's-eye view", lambda d: js(
        d, "const img = document.getElementById('birdseye'); return img.getAttribute('src') !== null &&"
           " document.body.dataset.birdseye === img.getAttribute('src') && img.complete;"))
    path = js(driver, "return document.getElementById('birdseye').getAttribute('src');")
    with open(os.path.join(work, f"out-{tag}", f"{CAMERA}-birdseye.png"), "rb") as f:
        expected = f.read()
    served, headers = console.api_bytes(driver, url, path)
    check(headers["Content-Type"] == "image/png", f"{tag}: the bird's-eye view's type {headers['Content-Type']}")
    check(served == expected, f"{tag}: the daemon's bird's-eye PNG ({len(served)} bytes) differs from"
                              f" linecal aftersale --out's ({len(expected)} bytes)")
    shown = driver.execute_async_script(COMPARE_PICTURES, base64.b64encode(expected).decode())
    check(shown.get("expected") == [320, 800] and shown.get("shown") == [320, 800] and shown.get("differing") == 0,
          f"{tag}: the bird's-eye view shown vs the command's: {shown}")
    return len(expected)


def check_links_stay_put(driver):
    """The header's links do not move while the live page fills in its station name, connection,
    cycle link, log-out and operator log-in links: a click aimed at one must not land on its
    neighbour (a CI run clicked "trends" for "after-sale" when the header changed between the
    aim and the click)."""
    moved = driver.execute_script(
        "const link = [...document.querySelectorAll('header a')].find((a) => a.textContent === 'after-sale');"
        " const before = link.getBoundingClientRect();"
        " const grown = ['station', 'connection', 'cycle-link'].map((id) => document.getElementById(id));"
        " const saved = grown.map((e) => [e.textContent, e.hidden]);"
        " for (const e of grown) { e.textContent += ' · a longer text than any the page shows'; e.hidden = false; }"
        " const toggled = ['logout', 'operator-login'].map((id) => document.getElementById(id));"
        " for (const e of toggled) e.hidden = !e.hidden;"
        " const after = link.getBoundingClientRect();"
        " grown.forEach((e, i) => { e.textContent = saved[i][0]; e.hidden = saved[i][1]; });"
        " for (const e of toggled) e.hidden = !e.hidden;"
        " return [before.x - after.x, before.y - after.y];")
    check(moved == [0, 0], f"the after-sale link moved by {moved} px as the header filled in")


def test(args, work):
    scene = os.path.join(work, "scene")
    run([args.linecal, "sim", "lanes", "--car", os.path.join(args.source_dir, "deploy/cars/reference.json"),
         "--camera", CAMERA, *SCENE, "--out", scene], "linecal sim lanes")
    with open(os.path.join(scene, "aftersale.json")) as f:
        truth = json.load(f)
    downloads = os.path.join(work, "downloads")
    os.makedirs(downloads)
    daemon, _, url = console.start_daemon(args.linecald, args.source_dir, work)
    driver = console.browser()
    try:
        shots = args.screenshots
        os.makedirs(shots, exist_ok=True)
        driver.execute_cdp_cmd("Browser.setDownloadBehavior", {"behavior": "allow", "downloadPath": downloads})
        # Log in, then reach the page by the live page's link.
        driver.get(url)
        wait(driver, "the login page", lambda d: "/login.html" in d.current_url)
        driver.find_element(By.ID, "token").send_keys(console.TOKEN)
        driver.find_element(By.ID, "login").click()
        wait(driver, "the live page", lambda d: d.current_url == url)
        check_links_stay_put(driver)
        driver.find_element(By.LINK_TEXT, "after-sale").click()
        wait(driver, "the after-sale page's address", lambda d: d.current_url.endswith("/aftersale.html"))
        wait(driver, "the after-sale page", lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-ready") == "true")
        select = Select(driver.find_element(By.ID, "camera"))
        select.select_by_visible_text(f"reference · {CAMERA} (1920×1080)")
        check(float(driver.find_element(By.ID, "camera-height").get_attribute("value")) == 1.35,
              "the camera's nominal height from the car model")
        driver.find_element(By.ID, "vin").send_keys(VIN)
        driver.find_element(By.ID, "photo").send_keys(os.path.join(scene, f"{CAMERA}.png"))
        wait(driver, "the photo", lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-photo") == "1920x1080")

        rect = canvas_rect(driver)
        scale = rect[2] / 1920
        check(rect[2] == round(rect[2]) and abs(view(driver)["scale"] - scale) < 1e-12,
              f"the fitted view: canvas {rect}, view {view(driver)}")
        expected = {"lane0": [], "lane1": [], "roll": [], "mark": []}
        pairs = []  # (the scene's point, the page's point)
        targets = [("lane0", p) for p in truth["lanes"][0]] + [("lane1", p) for p in truth["lanes"][1]] + \
                  [("roll", p) for p in truth["roll_line"]] + [("mark", truth["marked_point"]["uv_px"])]
        for tool, point in targets:
            driver.find_element(By.CSS_SELECTOR, f"input[name=tool][value={tool}]").click()
            placed, _ = place(driver, rect, scale, point)
            expected[tool].append(placed)
            pairs.append((point, placed))
        wait(driver, "every point placed", lambda d: sum(len(v) for v in page_points(d).values()) == len(targets))
        points = page_points(driver)
        for tool in expected:
            got, want = points[tool], expected[tool]
            check(len(got) == len(want) and all(abs(a - b) < 1e-9 for p, q in zip(got, want) for a, b in zip(p, q)),
                  f"{tool}: the page placed {got}, the pointer was over {want}")
        # The clicks are at most half a CSS pixel from the true points: 1 / (2 scale) image px.
        worst = max(abs(a - b) for point, placed in pairs for a, b in zip(point, placed))
        check(worst <= 0.5 / scale + 1e-9, f"a click {worst} px from its target (scale {scale})")
        # The magnifier shows the photo under the pointer.
        magnified = js(driver, "return Array.from(document.getElementById('magnifier').getContext('2d')"
                               ".getImageData(100, 100, 1, 1).data);")
        check(magnified[3] == 255, f"the magnifier is empty: {magnified}")

        distance = truth["marked_point"]["measured_distance_m"]
        driver.find_element(By.ID, "measured-distance").send_keys(str(distance))
        request = wait_solved_with(driver, points, distance)
        cli, _, compared = compare_with_command(driver, args, work, request, "clicked")
        birdseye_bytes = compare_birdseye(driver, url, work, "clicked")
        driver.save_screenshot(os.path.join(shots, "aftersale.png"))
        # The certificate: the VIN, the result, one printed page; its picture at A4's
        # proportions (794 x 1123 CSS px is A4 at 96 px an inch).
        check(driver.find_element(By.ID, "cert-vin").get_attribute("textContent") == VIN, "certificate VIN")
        check(values(driver, "cert-result", "ypr_deg") == cli["ypr_deg"], "certificate angles")
        pdf = base64.b64decode(driver.print_page())
        pages = len(re.findall(rb"/Type\s*/Page\b", pdf))
        check(pages == 1, f"the certificate prints on {pages} pages")
        size = driver.get_window_size()
        driver.set_window_size(794, 1123)
        driver.execute_cdp_cmd("Emulation.setEmulatedMedia", {"media": "print"})
        driver.save_screenshot(os.path.join(shots, "aftersale-certificate.png"))
        driver.execute_cdp_cmd("Emulation.setEmulatedMedia", {"media": ""})
        driver.set_window_size(size["width"], size["height"])
        # The page fits the photo again to the restored window (the A4 window's view is 200 px
        # wide, the restored one over 400 px); the view may differ by a pixel from the first.
        wait(driver, "the view refitted", lambda d: canvas_rect(d)[2] > 400 and
             abs(view(d)["scale"] - canvas_rect(d)[2] / 1920) < 1e-12)
        rect = canvas_rect(driver)
        scale = rect[2] / 1920
        check(abs(view(driver)["scale"] - scale) < 1e-12, f"the view refitted: {rect}, {view(driver)}")


        # Drag the marked point 40 px right and 12 px up: it follows the pointer, the result too.
        mark = page_points(driver)["mark"][0]
        x, y = round(rect[0] + (mark[0] + 0.5) * scale), round(rect[1] + (mark[1] + 0.5) * scale)
        actions = ActionBuilder(driver)
        actions.pointer_action.move_to_location(x, y).pointer_down()
        for step in range(1, 5):
            actions.pointer_action.move_to_location(x + 10 * step, y - 3 * step)
        actions.pointer_action.pointer_up()
        actions.perform()
        moved = [(x + 40 - rect[0]) / scale - 0.5, (y - 12 - rect[1]) / scale - 0.5]
        wait(driver, "the dragged point", lambda d: page_points(d)["mark"] == [moved] or
             all(abs(a - b) < 1e-9 for a, b in zip(page_points(d)["mark"][0], moved)))
        points = page_points(driver)
        request = wait_solved_with(driver, points, distance)
        cli, export, compared_after = compare_with_command(driver, args, work, request, "dragged")
        compare_birdseye(driver, url, work, "dragged")
        compared += compared_after

        # The wheel zooms around the pointer: the image point under it stays.
        before = view(driver)
        wheel_x, wheel_y = round(rect[0] + 300), round(rect[1] + 200)  # viewport px
        origin_x, origin_y = wheel_x - rect[0], wheel_y - rect[1]  # from the canvas's corner
        u_before = (origin_x / before["scale"] + before["left"], origin_y / before["scale"] + before["top"])
        ActionChains(driver).scroll_from_origin(ScrollOrigin.from_viewport(wheel_x, wheel_y), 0, -120).perform()
        wait(driver, "the zoom", lambda d: view(d)["scale"] > before["scale"])
        after = view(driver)
        check(abs(after["scale"] / before["scale"] - 1.25) < 1e-12, f"zoom {before} -> {after}")
        u_after = (origin_x / after["scale"] + after["left"], origin_y / after["scale"] + after["top"])
        check(all(abs(a - b) < 1e-6 for a, b in zip(u_before, u_after)), f"zoom moved the point under the pointer: {u_before} -> {u_after}")
        driver.find_element(By.ID, "fit").click()

        # The exports, downloaded: the command's files byte for byte.
        links = driver.find_elements(By.CSS_SELECTOR, "#export-links a.export")
        check(len(links) == 3, f"{len(links)} export links")
        for link in links + [driver.find_element(By.ID, "input-link")]:
            link.click()
        names = sorted(os.listdir(export)) + ["aftersale.json"]
        wait(driver, "the downloads", lambda d: sorted(os.listdir(downloads)) == sorted(names))
        for name in sorted(os.listdir(export)):
            with open(os.path.join(export, name), "rb") as a, open(os.path.join(downloads, name), "rb") as b:
                check(a.read() == b.read(), f"{name}: the page's download differs from linecal aftersale --export's")
        with open(os.path.join(downloads, "aftersale.json")) as f:
            given = json.load(f)
        check(given == dict(request["input"], image=f"{CAMERA}.png"), f"the input download: {given}")

        # A lane point dragged above the horizon: the page shows the command's refusal. Its
        # refused POST is the one console error allowed ("Failed to load resource ... 400").
        check(not console.errors(driver), "console errors before the refusal")
        # Clicking the links scrolled the page to them: back to the top, where the view was.
        js(driver, "window.scrollTo(0, 0);")
        rect = canvas_rect(driver)
        first = page_points(driver)["lane0"][0]
        x, y = round(rect[0] + (first[0] + 0.5) * scale), round(rect[1] + (first[1] + 0.5) * scale)
        actions = ActionBuilder(driver)
        actions.pointer_action.move_to_location(x, y).pointer_down()
        actions.pointer_action.move_to_location(x, round(rect[1] + 20)).pointer_up()
        actions.perform()
        wait(driver, "the refusal", lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-refused"))
        refused = json.loads(driver.find_element(By.TAG_NAME, "body").get_attribute("data-refused"))
        path = os.path.join(work, "input-refused.json")
        with open(path, "w") as f:
            json.dump(dict(refused["input"], image=os.path.join(scene, f"{CAMERA}.png")), f)
        out = subprocess.run([args.linecal, "aftersale", "--input", path], capture_output=True, text=True,
                             timeout=console.WAIT_S)
        check(out.returncode == 2 and "above the horizon" in out.stderr, f"the command on the refused points: {out.stderr}")
        message = driver.find_element(By.ID, "message").text
        check("Refused: " + out.stderr.removeprefix("linecal aftersale: ").strip() == message,
              f"the page says '{message}', the command '{out.stderr.strip()}'")
        check(driver.find_element(By.ID, "result").get_attribute("hidden") is not None, "a refused result is hidden")
        check(driver.find_element(By.ID, "birdseye-figure").get_attribute("hidden") is not None,
              "no bird's-eye view of a refused result")
        refused_errors = console.errors(driver)
        check(len(refused_errors) == 1 and "/api/aftersale" in refused_errors[0]["message"]
              and "400" in refused_errors[0]["message"], f"console errors at the refusal: {refused_errors}")

        solve_ms = sorted(json.loads(driver.find_element(By.TAG_NAME, "body").get_attribute("data-solve-ms")))
        print(f"after-sale page: {len(solve_ms)} solves, points sent to overlay drawn: median "
              f"{solve_ms[len(solve_ms) // 2]:.1f} ms, worst {solve_ms[-1]:.1f} ms")
        print(f"after-sale page: {sum(len(v) for v in points.values())} points clicked at scale {scale:.4f} "
              f"(worst {worst:.3f} px from the scene's points), {compared} numbers equal to linecal aftersale's, "
              f"3 export files equal byte for byte, certificate on {pages} page")
        print(f"after-sale page: the bird's-eye view ({birdseye_bytes} bytes of PNG) equal byte for byte and"
              " pixel for pixel to linecal aftersale --out's, after the clicks and after the drag")
        left = console.errors(driver)
        check(not left, f"console errors: {left}")
    finally:
        driver.quit()
        console.stop(daemon)


def main():
    return console.run_main(__doc__, "aftersale_browser_", "folder for aftersale.png, aftersale-certificate.png", test)


if __name__ == "__main__":
    sys.exit(main())
