#!/usr/bin/python3
"""The station console in a real headless Chromium (Debian's chromium, chromium-driver and
python3-selenium) against a real linecald with the simulator source (docs/console.md,
"Tests"): the login page refuses a wrong token and lets the right one in; a cycle started
over gRPC (the linecal CLI) is watched live on the station page to its end, every sensor's
verdict shown as GetCycle has it and within the 200 ms bar of its event; the cycle page shows
GetCycle's numbers; the browser logs no errors. Screenshots of each page go to --screenshots.

Exit 0 passed, 1 failed, 77 skipped (ctest's SKIP_RETURN_CODE) when Chromium, its driver or
Selenium is missing, saying which.
"""
import argparse
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"
VIN = "1M8GDM9AXKP042788"
TOKEN = "line-3-browser-token"
OPERATOR_TOKEN = "line-3-operator-token"
# docs/console.md "Bars": a sensor's verdict on the live page within 200 ms of its event.
VERDICT_BAR_MS = 200.0
# Every wait's bound: a full reference-car cycle takes about 4 s in Release; 60 s is a hung
# page, not a slow one.
WAIT_S = 60


def skip(why):
    print(f"SKIP: {why}")
    sys.exit(77)


try:
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait
except ImportError as e:
    skip(f"python3-selenium is not installed ({e}); tools/setup installs it")


class Failure(Exception):
    pass


def check(condition, message):
    if not condition:
        raise Failure(message)


def start_daemon(linecald, source_dir, work):
    config = {
        "listen": "127.0.0.1:0",
        "auth_token": TOKEN,
        "station": os.path.join(source_dir, "deploy/stations/reference.json"),
        "car_models": [os.path.join(source_dir, "deploy/cars/reference.json")],
        "data_root": "data",
        "web": {"listen": "127.0.0.1:0", "operator_token": OPERATOR_TOKEN},
    }
    os.makedirs(os.path.join(work, "data"), exist_ok=True)
    return launch_daemon(linecald, work, config)


def launch_daemon(linecald, work, config):
    """linecald on `config` (written to work/linecald.json), its log in work/linecald.log; waits
    for its gRPC port and console address (the last ones the log names: a restart appends)."""
    path = os.path.join(work, "linecald.json")
    with open(path, "w") as f:
        json.dump(config, f)
    log = open(os.path.join(work, "linecald.log"), "w+")
    daemon = subprocess.Popen([linecald, "--config", path], stderr=log, stdout=log)
    deadline = time.time() + WAIT_S
    grpc_port = web_url = None
    while time.time() < deadline and (grpc_port is None or web_url is None):
        check(daemon.poll() is None, f"linecald exited: {open(log.name).read()}")
        text = open(log.name).read()
        m = re.findall(r"\(port (\d+)\)", text)
        grpc_port = m[-1] if m else None
        m = re.findall(r"console on (http://127\.0\.0\.1:\d+/)", text)
        web_url = m[-1] if m else None
        time.sleep(0.05)
    check(grpc_port and web_url, f"linecald did not say where it listens: {open(log.name).read()}")
    return daemon, f"127.0.0.1:{grpc_port}", web_url


def stop(daemon):
    """SIGTERM, then SIGKILL after 30 s."""
    daemon.send_signal(signal.SIGTERM)
    try:
        daemon.wait(timeout=30)
    except subprocess.TimeoutExpired:
        daemon.kill()


def linecal(cli, address, *args):
    out = subprocess.run([cli, *args, "--address", address, "--token", TOKEN, "--json"],
                         capture_output=True, text=True, timeout=WAIT_S)
    check(out.returncode in (0, 1), f"linecal {' '.join(args)}: {out.returncode} {out.stderr}")
    return json.loads(out.stdout)


def browser():
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    options.add_argument("--headless=new")
    # Root in containers and CI: Chromium's sandbox needs user namespaces it may not have.
    options.add_argument("--no-sandbox")
    options.add_argument("--disable-dev-shm-usage")
    options.add_argument("--window-size=1600,1000")
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)


def errors(driver):
    """The browser's console entries of level SEVERE since the last call (reading clears)."""
    return [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]


def page_state(driver):
    """Where a failed wait left the browser: the page's address, its message line (where the
    pages show an error) and the browser's console errors, so a failure says why."""
    try:
        message = driver.find_elements(By.ID, "message")
        text = message[0].text if message else ""
        return f"at {driver.current_url}, message {text!r}, browser errors {errors(driver)}"
    except Exception as e:  # the browser itself gone: say so rather than hide the first error
        return f"browser state unreadable: {e}"


def wait(driver, what, condition):
    try:
        return WebDriverWait(driver, WAIT_S, poll_frequency=0.02).until(lambda d: condition(d))
    except Exception as e:
        raise Failure(f"timed out waiting for {what}: {e}; {page_state(driver)}")


def verdict_word(proto_verdict):
    return {"VERDICT_PASS": "pass", "VERDICT_FAIL": "fail", "VERDICT_ERROR": "error"}.get(proto_verdict, "")


def test(args, work):
    daemon, address, url = start_daemon(args.linecald, args.source_dir, work)
    driver = browser()
    try:
        shots = args.screenshots
        os.makedirs(shots, exist_ok=True)
        # Not logged in: the live page sends the browser to the login page.
        driver.get(url)
        wait(driver, "the login page", lambda d: "/login.html" in d.current_url)
        check(driver.current_url.endswith("/login.html?next=%2f"), driver.current_url)
        driver.find_element(By.ID, "token").send_keys("not-the-token")
        driver.find_element(By.ID, "login").click()
        wait(driver, "the refusal", lambda d: d.find_element(By.ID, "login-message").text == "Wrong token.")
        check("/login.html" in driver.current_url, "a wrong token left the login page")
        driver.save_screenshot(os.path.join(shots, "login.png"))
        # The refused POST is the one error Chromium logs here ("Failed to load resource ... 401").
        refused = errors(driver)
        check(len(refused) == 1 and "/api/login" in refused[0]["message"] and "401" in refused[0]["message"],
              f"console errors at the refusal: {refused}")
        token = driver.find_element(By.ID, "token")
        token.clear()
        token.send_keys(TOKEN)
        driver.find_element(By.ID, "login").click()
        wait(driver, "the live page", lambda d: d.current_url == url)
        wait(driver, "the event stream", lambda d: d.find_element(By.ID, "connection").text == "live")
        cookies = driver.get_cookies()
        check(len(cookies) == 1 and cookies[0]["name"] == "linecal_session" and cookies[0]["httpOnly"]
              and cookies[0]["sameSite"] == "Strict" and TOKEN not in cookies[0]["value"],
              f"session cookie: {cookies}")

        # A cycle over gRPC, watched live: the page must show it running, then each verdict.
        started = linecal(args.linecal, address, "cycle", "start", "--vin", VIN, "--car", "reference")
        cycle_id = str(started["cycle_id"]) if isinstance(started, dict) else str(started)
        seen_running = False
        verdicts_seen_while_running = 0
        deadline = time.time() + WAIT_S
        while time.time() < deadline:
            body = driver.find_element(By.TAG_NAME, "body")
            if body.get_attribute("data-ended") == cycle_id:
                break
            if body.get_attribute("data-cycle") == cycle_id:
                badge = driver.find_element(By.ID, "cycle-verdict").text
                if badge == "running":
                    seen_running = True
                    rows = driver.find_elements(By.CSS_SELECTOR, "#sensors tr[data-verdict]")
                    verdicts_seen_while_running = max(verdicts_seen_while_running, len(rows))
            time.sleep(0.02)
        check(driver.find_element(By.TAG_NAME, "body").get_attribute("data-ended") == cycle_id,
              "the live page did not show the cycle's end")
        check(seen_running, "the live page never showed the cycle running")
        driver.save_screenshot(os.path.join(shots, "live.png"))

        cycle = linecal(args.linecal, address, "cycle", "show", cycle_id)
        check(driver.find_element(By.ID, "vin").text == VIN, "VIN")
        check(driver.find_element(By.ID, "model").text == "reference", "model")
        check(driver.find_element(By.ID, "cycle-verdict").text == verdict_word(cycle["verdict"]),
              f"cycle verdict {driver.find_element(By.ID, 'cycle-verdict').text} vs {cycle['verdict']}")
        rows = {r.get_attribute("data-sensor"): r for r in driver.find_elements(By.CSS_SELECTOR, "#sensors tr")}
        check(sorted(rows) == sorted(s["name"] for s in cycle["sensors"]),
              f"rows {sorted(rows)} vs sensors {[s['name'] for s in cycle['sensors']]}")
        delays = {}
        for s in cycle["sensors"]:
            row = rows[s["name"]]
            word = verdict_word(s["verdict"])
            check(row.get_attribute("data-verdict") == word, f"{s['name']}: {row.get_attribute('data-verdict')} vs {word}")
            check(row.find_element(By.CLASS_NAME, "verdict").text == word.upper(), f"{s['name']}: verdict text")
            check(row.find_element(By.CLASS_NAME, "step").text == "done", f"{s['name']}: step")
            reason = row.find_element(By.CLASS_NAME, "reason").text
            check(reason == ("" if word == "pass" else s.get("reason", "")), f"{s['name']}: reason '{reason}'")
            delays[s["name"]] = float(row.get_attribute("data-shown-after-ms"))
        worst = max(delays.values())
        print(f"verdicts on the live page after their events: worst {worst:.1f} ms, "
              f"mean {sum(delays.values()) / len(delays):.1f} ms over {len(delays)} sensors; "
              f"{verdicts_seen_while_running} verdicts seen before the cycle's end")
        check(worst <= VERDICT_BAR_MS, f"a verdict took {worst:.1f} ms to show (bar {VERDICT_BAR_MS} ms): {delays}")

        # The cycle page: GetCycle's numbers, exactly, and the car file's tolerances.
        driver.find_element(By.ID, "cycle-link").click()
        wait(driver, "the cycle page", lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-loaded") == cycle_id)
        driver.save_screenshot(os.path.join(shots, "cycle.png"))
        with open(os.path.join(args.source_dir, "deploy/cars/reference.json")) as f:
            car = {s["name"]: s for s in json.load(f)["sensors"]}
        axes = [("yaw_deg", 3, 0), ("pitch_deg", 3, 1), ("roll_deg", 3, 2), ("x_m", 4, 0), ("y_m", 4, 1), ("z_m", 4, 2)]
        compared = 0
        for s in cycle["sensors"]:
            section = driver.find_element(By.CSS_SELECTOR, f"section.sensor[data-sensor='{s['name']}']")
            for axis, digits, index in axes:
                row = section.find_element(By.CSS_SELECTOR, f"tr[data-axis='{axis}']")
                cells = {c: row.find_element(By.CSS_SELECTOR, f"td.{c.split()[0]}") for c in
                         ("found", "nominal", "deviation", "tolerance", "sigma")}
                for cls, group in (("found", "mounting"), ("deviation", "deviation"), ("sigma", "uncertainty")):
                    expected = s.get(group, {}).get(axis, 0.0)  # proto JSON leaves zeros out
                    shown = float(cells[cls].get_attribute("data-value"))
                    check(shown == expected, f"{s['name']} {axis} {cls}: {shown} vs GetCycle {expected}")
                    text = float(cells[cls].text)
                    check(abs(text - expected) <= 0.5 * 10 ** -digits + 1e-12,
                          f"{s['name']} {axis} {cls}: shown '{cells[cls].text}' vs {expected}")
                    compared += 1
                key = "ypr_deg" if axis.endswith("_deg") else "xyz_m"
                tolerance = float(cells["tolerance"].get_attribute("data-value"))
                # The car file's degrees went to radians and back: equal to 1e-12.
                check(abs(tolerance - car[s["name"]]["tolerance"][key][index]) < 1e-12,
                      f"{s['name']} {axis} tolerance {tolerance}")
                nominal = float(cells["nominal"].get_attribute("data-value"))
                found = s.get("mounting", {}).get(axis, 0.0)
                deviation = s.get("deviation", {}).get(axis, 0.0)
                # The nominal the deviation was measured from, to rounding (1e-9).
                check(abs(nominal - (found - deviation)) < 1e-9, f"{s['name']} {axis} nominal {nominal}")
            residual = float(section.find_element(By.CLASS_NAME, "residual").get_attribute("data-value"))
            check(residual == s.get("residual_rms", 0.0), f"{s['name']} residual {residual}")
        print(f"cycle page: {compared} numbers equal to GetCycle's over {len(cycle['sensors'])} sensors")

        left = errors(driver)
        check(not left, f"console errors: {left}")

        operated = operator_cycle(driver, args, address, url, shots)
        cycle_views(driver, url, operated, shots)
        left = errors(driver)
        check(not left, f"console errors: {left}")
    finally:
        driver.quit()
        stop(daemon)


def operator_cycle(driver, args, address, url, shots):
    """An operator logs in from the live page, starts a cycle that keeps its capture, and the
    page shows it to its end; GetCycle has it done with the VIN typed. Returns its id."""
    driver.get(url)
    wait(driver, "the operator log-in link", lambda d: d.find_element(By.ID, "operator-login").is_displayed())
    check(not driver.find_elements(By.ID, "operator"), "a read-only session shows the operator's controls")
    driver.find_element(By.ID, "operator-login").click()
    wait(driver, "the login page", lambda d: "/login.html" in d.current_url)
    driver.find_element(By.ID, "token").send_keys(OPERATOR_TOKEN)
    driver.find_element(By.ID, "login").click()
    wait(driver, "the operator's controls", lambda d: d.find_elements(By.ID, "op-start"))
    wait(driver, "the event stream", lambda d: d.find_element(By.ID, "connection").text == "live")
    driver.find_element(By.ID, "op-vin").send_keys(VIN)
    check(driver.find_element(By.ID, "op-model").get_attribute("value") == "reference", "car model choice")
    driver.find_element(By.ID, "op-record").click()
    driver.find_element(By.ID, "op-start").click()
    form = driver.find_element(By.ID, "operator")
    cycle_id = wait(driver, "the started cycle", lambda d: form.get_attribute("data-started"))
    wait(driver, "the cycle's end", lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-ended") == cycle_id)
    driver.save_screenshot(os.path.join(shots, "operator.png"))
    cycle = linecal(args.linecal, address, "cycle", "show", cycle_id)
    check(cycle["vin"] == VIN and cycle["state"] == "CYCLE_STATE_DONE",
          f"the operator's cycle: {cycle['vin']} {cycle['state']}")
    check(driver.find_element(By.ID, "op-start").is_enabled(), "start stays disabled after the end")
    print(f"operator: cycle {cycle_id} started from the live page, ended {verdict_word(cycle['verdict'])}")
    return cycle_id


def api_json(driver, url, path):
    """GET an API path with the browser's session cookie (outside the page: no console entry)."""
    import urllib.request
    cookie = "; ".join(f"{c['name']}={c['value']}" for c in driver.get_cookies())
    with urllib.request.urlopen(urllib.request.Request(url.rstrip("/") + path, headers={"Cookie": cookie})) as r:
        return json.load(r)


def api_bytes(driver, url, path):
    """GET a path with the browser's session cookie: (bytes, headers)."""
    import urllib.request
    cookie = "; ".join(f"{c['name']}={c['value']}" for c in driver.get_cookies())
    with urllib.request.urlopen(urllib.request.Request(url.rstrip("/") + path, headers={"Cookie": cookie})) as r:
        return r.read(), r.headers


def capture_archive(driver, url, cycle_id, capture):
    """The cycle page's link to the whole capture: a tar holding every listed file under
    cycle-ID/, byte for byte as the file's own download."""
    import io
    import tarfile
    link = driver.find_element(By.ID, "capture-archive")
    href = link.get_attribute("href")
    check(href == f"{url}api/cycles/{cycle_id}/capture.tar", f"the archive's link: {href}")
    check(link.get_attribute("download") is not None, "the archive's link is a download")
    tar, headers = api_bytes(driver, url, f"/api/cycles/{cycle_id}/capture.tar")
    check(headers["Content-Disposition"] == f'attachment; filename="cycle-{cycle_id}-capture.tar"',
          f"the archive's name: {headers['Content-Disposition']}")
    with tarfile.open(fileobj=io.BytesIO(tar), mode="r:") as archive:
        members = {m.name: archive.extractfile(m).read() for m in archive.getmembers() if m.isfile()}
    for f in capture["files"]:
        name = f"cycle-{cycle_id}/{f['path']}"
        check(name in members, f"{name} is not in the archive: {sorted(members)}")
        own, _ = api_bytes(driver, url, f"/api/cycles/{cycle_id}/capture/{f['index']}")
        check(members[name] == own, f"{name}: the archive's bytes differ from the file's download")
    print(f"capture archive: {len(members)} files, {len(tar)} bytes, the {len(capture['files'])} listed"
          " files equal to their downloads")


def cycle_views(driver, url, cycle_id, shots):
    """The cycle page of a cycle with a capture: every camera's frame loads at its size and
    shows as many detected features as the API's view has; the LiDAR and radar views draw
    the API's fitted boards and found reflectors; the capture's files are linked."""
    driver.get(f"{url}cycle.html?id={cycle_id}")
    wait(driver, "the views", lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-views") == cycle_id)
    capture = api_json(driver, url, f"/api/cycles/{cycle_id}/capture")
    links = driver.find_elements(By.CSS_SELECTOR, "#capture ul.files a")
    check(len(links) == len(capture["files"]), f"{len(links)} capture links for {len(capture['files'])} files")
    capture_archive(driver, url, cycle_id, capture)
    counts = []
    for figure in driver.find_elements(By.CSS_SELECTOR, "figure.camera-view"):
        sensor = figure.get_attribute("data-sensor")
        view = api_json(driver, url, f"/api/cycles/{cycle_id}/views/{sensor}")
        wait(driver, f"{sensor}'s frame", lambda d: figure.get_attribute("data-image-loaded"))
        loaded = int(figure.get_attribute("data-image-loaded"))
        check(loaded == view["width"], f"{sensor}: frame {loaded} px wide, the view says {view['width']}")
        drawn = len(figure.find_elements(By.CSS_SELECTOR, "circle.detected"))
        check(drawn == view["detected_features"], f"{sensor}: {drawn} features drawn, API {view['detected_features']}")
        crosses = len(figure.find_elements(By.CSS_SELECTOR, "path.reprojected"))
        check(crosses == view["reprojected_features"], f"{sensor}: {crosses} reprojected, API {view['reprojected_features']}")
        counts.append(f"{sensor} {drawn}")
    cameras = [s["name"] for s in api_json(driver, url, f"/api/cycles/{cycle_id}")["sensors"] if s["kind"] == "camera"]
    check(len(counts) == len(cameras), f"camera views: {counts} for the cameras {cameras}")
    for figure in driver.find_elements(By.CSS_SELECTOR, "figure.lidar-view"):
        view = api_json(driver, url, f"/api/cycles/{cycle_id}/views/{figure.get_attribute('data-sensor')}")
        fitted = len(figure.find_elements(By.CSS_SELECTOR, "polygon.fitted"))
        check(fitted == sum(1 for b in view["boards"] if b["found"]), f"lidar: {fitted} boards drawn")
        check(int(figure.get_attribute("data-points")) == len(view["points"]), "lidar: points drawn")
    for figure in driver.find_elements(By.CSS_SELECTOR, "figure.radar-view"):
        view = api_json(driver, url, f"/api/cycles/{cycle_id}/views/{figure.get_attribute('data-sensor')}")
        found = len(figure.find_elements(By.CSS_SELECTOR, "circle.found"))
        check(found == sum(1 for r in view["reflectors"] if r["status"] == "found"), f"radar: {found} found drawn")
    check(driver.find_elements(By.CSS_SELECTOR, "figure.lidar-view") and
          driver.find_elements(By.CSS_SELECTOR, "figure.radar-view"), "lidar and radar views")
    for cls, name in (("camera-view", "cycle-camera.png"), ("lidar-view", "cycle-lidar.png"),
                      ("radar-view", "cycle-radar.png")):
        figure = driver.find_element(By.CSS_SELECTOR, f"figure.{cls}")
        driver.execute_script("arguments[0].scrollIntoView()", figure)
        figure.screenshot(os.path.join(shots, name))
    print(f"cycle views: features drawn equal to the API's: {', '.join(counts)}")


def run_main(description, work_prefix, screenshots_help, test_fn):
    """The browser tests' command line: flags, the skip without Chromium, a scratch folder,
    the daemon's log on a failure. `test_fn(args, work)` raises Failure. The exit code."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--linecald", required=True)
    parser.add_argument("--linecal", required=True)
    parser.add_argument("--source-dir", required=True)
    parser.add_argument("--screenshots", required=True, help=screenshots_help)
    args = parser.parse_args()
    for path, package in ((CHROMIUM, "chromium"), (CHROMEDRIVER, "chromium-driver")):
        if not os.access(path, os.X_OK):
            skip(f"{path} is missing: install Debian's {package} (tools/setup does)")
    work = tempfile.mkdtemp(prefix=work_prefix)
    try:
        test_fn(args, work)
    except Failure as e:
        print(f"FAILED: {e}")
        log = os.path.join(work, "linecald.log")
        print(open(log).read() if os.path.exists(log) else "")
        return 1
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print("PASSED")
    return 0


def main():
    return run_main(__doc__, "console_browser_", "folder for login.png, live.png, cycle.png", test)


if __name__ == "__main__":
    sys.exit(main())
