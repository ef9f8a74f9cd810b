#!/usr/bin/python3
"""The trends page in a real headless Chromium against a real linecald with the simulator
source (docs/console.md, "Trends and station health"): 30 cycles of a car with the sensors of
the bumper boards, `bumper_lidar_left` turned 0.3 degrees by the simulator from cycle 16
(source.moved_boards); the page shows the alarm naming it, from the same cycle as `linecal
status --json` (gRPC), and the browser logs no errors. Then 10,000 cycles of those results are
added to the database: the cycles list (cycles.html) against ListCycles, with its filters, and
the speed of the 1,000-cycle list, of 1,000- and 10,000-cycle trends measured in the page
(printed, not asserted: docs/console.md's table). Screenshots go to --screenshots.

Exit 0 passed, 1 failed, 77 skipped when Chromium, its driver or Selenium is missing.
"""
import json
import os
import random
import sqlite3
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from console_browser_test import (TOKEN, VIN, WAIT_S, By, Failure,  # noqa: E402
                                  browser, check, errors, launch_daemon, run_main, stop, wait)

CYCLES = 30
MOVED_FROM = 16  # midway
MOVED_BOARD = "bumper_lidar_left"
# The sensors that use the bumper boards, and one that does not (a bystander that must not
# be named): the reference car cut down so that 30 cycles take about a minute.
SENSORS = ("front_camera", "surround_front", "surround_left", "bumper_lidar")
# Cycles added for the speed measurements (issue 23's bars: 1,000 and 10,000).
ADDED = 10000


def start_daemon(linecald, source_dir, work):
    with open(os.path.join(source_dir, "deploy/cars/reference.json")) as f:
        car = json.load(f)
    car["sensors"] = [s for s in car["sensors"] if s["name"] in SENSORS]
    with open(os.path.join(work, "car.json"), "w") as f:
        json.dump(car, f)
    config = {
        "listen": "127.0.0.1:0",
        "auth_token": TOKEN,
        "station": os.path.join(source_dir, "deploy/stations/reference.json"),
        "car_models": [os.path.join(work, "car.json")],
        "data_root": "data",
        "source": {"type": "simulator",
                   "moved_boards": [{"board": MOVED_BOARD, "ypr_deg": [0.3, 0, 0], "from_cycle": MOVED_FROM}]},
        "web": {"listen": "127.0.0.1:0"},
    }
    os.makedirs(os.path.join(work, "data"), exist_ok=True)
    return launch_daemon(linecald, work, config)


def linecal(cli, address, *args):
    out = subprocess.run([cli, *args, "--address", address, "--token", TOKEN, "--json"],
                         capture_output=True, text=True, timeout=WAIT_S)
    check(out.returncode in (0, 1), f"linecal {' '.join(args)}: {out.returncode} {out.stderr}")
    return json.loads(out.stdout)


def login(driver, url, page):
    driver.get(url + page)
    wait(driver, "the login page", lambda d: "/login.html" in d.current_url)
    driver.find_element(By.ID, "token").send_keys(TOKEN)
    driver.find_element(By.ID, "login").click()
    wait(driver, "the trends page", lambda d: "/trends.html" in d.current_url)


def open_trends(driver, url, query):
    driver.get(f"{url}trends.html?{query}")
    wait(driver, f"trends {query}", lambda d: d.execute_script("return document.body.dataset.loaded"))
    return driver.execute_script(
        "const b = document.body.dataset;"
        "return {points: +b.points, fetch_ms: +b.fetchMs, draw_ms: +b.drawMs, loaded_ms: +b.drawnAtMs,"
        " requests: requests()};" + REQUESTS)


# The page's requests as "path start-end" (ms since the navigation started; a 304 has a small
# transferSize): what costs what in a page's load.
REQUESTS = ("function requests() { return performance.getEntriesByType('resource').map((e) =>"
            " `${e.name.replace(location.origin, '')} ${e.startTime.toFixed(0)}-${e.responseEnd.toFixed(0)}`"
            " + (e.transferSize < 400 ? ' (cached)' : '')).join(', '); }")


def open_cycles(driver, url, query):
    """The cycles list at `query`: its rows' cycle ids, verdicts and VINs, and when the table
    was drawn (ms since the navigation started)."""
    driver.get(f"{url}cycles.html?{query}")
    wait(driver, f"cycles {query}", lambda d: d.execute_script("return document.body.dataset.loaded"))
    return driver.execute_script(
        "const rows = [...document.querySelectorAll('#cycles tr')];"
        "return {ids: rows.map((r) => r.dataset.cycle), vins: rows.map((r) => r.cells[1].textContent),"
        " verdicts: rows.map((r) => r.cells[6].textContent), loaded_ms: +document.body.dataset.drawnAtMs,"
        " older: document.getElementById('older').hidden ? '' : document.getElementById('older').href,"
        " message: document.getElementById('cycles-message').textContent, requests: requests()};" + REQUESTS)


def check_cycles_list(driver, url, address, cli, shots):
    """The cycles list against the API's ListCycles (gRPC, `linecal cycle list`): the newest
    1,000, a VIN's, none failed, and the link to the next page."""
    listed = linecal(cli, address, "cycles", "list", "--limit", "1000")
    grpc_ids = [str(c.get("cycleId", c.get("cycle_id"))) for c in listed.get("cycles", listed)]
    page = open_cycles(driver, url, "limit=1000")
    check(page["ids"] == grpc_ids, f"cycles page ids {page['ids'][:3]}... differ from ListCycles' {grpc_ids[:3]}...")
    check(f"before={grpc_ids[-1]}" in page["older"], f"the older link: {page['older']}")
    driver.save_screenshot(os.path.join(shots, "cycles.png"))
    page = open_cycles(driver, url, f"vin={VIN}&limit=50")
    check(len(page["ids"]) == 50 and set(page["vins"]) == {VIN}, f"VIN filter: {set(page['vins'])}")
    failed = linecal(cli, address, "cycles", "list", "--verdict", "fail", "--limit", "50")
    failed_ids = [str(c.get("cycleId", c.get("cycle_id"))) for c in failed.get("cycles", [])]
    page = open_cycles(driver, url, "verdict=fail&limit=50")
    check(page["ids"] == failed_ids and set(page["verdicts"]) <= {"FAIL"}, f"verdict filter: {page}")
    page = open_cycles(driver, url, "vin=NO0SUCH0VIN&limit=50")
    check(page["ids"] == [] and page["message"] == "No cycle matches.", f"an unknown VIN: {page}")
    print(f"cycles page: the newest 1,000 equal to ListCycles', filters by VIN and verdict"
          f" ({len(failed_ids)} failed cycles)")


def add_cycles(db, count):
    """Appends `count` done cycles whose sensor and board results are copies of the stored ones, in
    turn."""
    con = sqlite3.connect(db)
    cycles = con.execute("SELECT vin, car_model_id, started_ns, request_json FROM cycles ORDER BY id").fetchall()
    results = {}
    columns = [r[1] for r in con.execute("PRAGMA table_info(sensor_results)")]
    for row in con.execute("SELECT * FROM sensor_results ORDER BY cycle_id"):
        results.setdefault(row[0], []).append(row)
    boards = {}
    for row in con.execute("SELECT * FROM board_results ORDER BY cycle_id"):
        boards.setdefault(row[0], []).append(row)
    source_ids = sorted(results)
    next_id = con.execute("SELECT max(id) FROM cycles").fetchone()[0] + 1
    started = cycles[-1][2]
    marks = ",".join("?" * len(columns))
    with con:
        for k in range(count):
            vin, model, _, request = cycles[k % len(cycles)]
            started += 60_000_000_000
            con.execute("INSERT INTO cycles (id, vin, car_model_id, state, verdict, reason, started_ns, ended_ns,"
                        " request_json) VALUES (?, ?, ?, 'done', 'pass', '', ?, ?, ?)",
                        (next_id + k, vin, model, started, started + 5_000_000_000, request))
            for row in results[source_ids[k % len(source_ids)]]:
                con.execute(f"INSERT INTO sensor_results VALUES ({marks})", (next_id + k, *row[1:]))
            for row in boards.get(source_ids[k % len(source_ids)], []):
                con.execute("INSERT INTO board_results VALUES (?, ?, ?, ?, ?, ?, ?)", (next_id + k, *row[1:]))
    con.close()


def test(args, work):
    daemon, address, url = start_daemon(args.linecald, args.source_dir, work)
    driver = browser()
    try:
        rng = random.Random(7)  # the aligner's reading of each car, within its bounds
        for _ in range(CYCLES):
            linecal(args.linecal, address, "cycle", "start", "--vin", VIN, "--car", "reference",
                    "--lateral-m", f"{rng.uniform(-0.02, 0.02):.4f}",
                    "--longitudinal-m", f"{rng.uniform(-0.02, 0.02):.4f}",
                    "--thrust-deg", f"{rng.uniform(-0.2, 0.2):.3f}", "--wait")
        status = linecal(args.linecal, address, "status")
        alarms = status.get("targetAlarms", status.get("target_alarms", []))
        check(len(alarms) == 1, f"gRPC status alarms: {alarms}")
        alarm = alarms[0]
        check(MOVED_BOARD in alarm["targets"], f"the alarm names {alarm['targets']}")
        named = [s["sensor"] for s in alarm["sensors"]]
        check(named == ["front_camera", "surround_front", "bumper_lidar"], f"the alarm's sensors: {named}")
        since = int(alarm.get("sinceCycleId", alarm.get("since_cycle_id")))
        print(f"gRPC status: {alarm}")

        login(driver, url, f"trends.html?sensor=front_camera&cycles={CYCLES}")
        wait(driver, "the trends", lambda d: d.execute_script("return document.body.dataset.loaded"))
        banners = driver.find_elements(By.CLASS_NAME, "alarm")
        check(len(banners) == 1, f"alarm banners: {[b.text for b in banners]}")
        text = banners[0].text
        check(MOVED_BOARD in text and f"since cycle {since}:" in text, f"the banner: {text}")
        check(since <= CYCLES and since >= MOVED_FROM - 5, f"the rise starts at cycle {since}")
        charts = driver.find_elements(By.CSS_SELECTOR, "#charts canvas")
        check(len(charts) == 7, f"{len(charts)} charts")
        os.makedirs(args.screenshots, exist_ok=True)
        driver.save_screenshot(os.path.join(args.screenshots, "trends.png"))
        print(f"trends page: the alarm names {MOVED_BOARD} since cycle {since} (moved from {MOVED_FROM})")
        left = errors(driver)
        check(not left, f"console errors: {left}")

        # Speed (issue 23's bars), measured and printed: docs/console.md has the table.
        stop(daemon)
        add_cycles(os.path.join(work, "data", "linecal.db"), ADDED)
        daemon, address, url = start_daemon(args.linecald, args.source_dir, work)
        login(driver, url, "trends.html?sensor=front_camera&cycles=1000")
        check_cycles_list(driver, url, address, args.linecal, args.screenshots)
        for attempt in range(3):
            m = open_cycles(driver, url, "limit=1000")
            check(len(m["ids"]) == 1000, f"{len(m['ids'])} rows")
            print(f"speed cycles.html?limit=1000 run {attempt + 1}: 1000 rows drawn {m['loaded_ms']:.0f} ms after"
                  f" the navigation started; requests: {m['requests']}")
        for query in ("sensor=front_camera&cycles=1000", "sensor=front_camera&cycles=10000"):
            for attempt in range(3):
                m = open_trends(driver, url, query)
                print(f"speed trends.html?{query} run {attempt + 1}: {m['points']} cars, charts drawn"
                      f" {m['loaded_ms']:.0f} ms after the navigation started (trends fetched in"
                      f" {m['fetch_ms']:.0f} ms, drawn in {m['draw_ms']:.0f} ms); requests: {m['requests']}")
        for attempt in range(3):
            listed = driver.execute_script(
                "const t = performance.now(); return fetch('/api/cycles?limit=1000').then((r) => r.json())"
                ".then((b) => [b.cycles.length, performance.now() - t]);")
            print(f"speed /api/cycles?limit=1000 run {attempt + 1}: {listed[0]} cycles fetched and parsed"
                  f" in {listed[1]:.0f} ms")
        left = errors(driver)
        check(not left, f"console errors: {left}")
    finally:
        driver.quit()
        stop(daemon)


def main():
    return run_main(__doc__, "trends_browser_", "folder for trends.png and cycles.png", test)


if __name__ == "__main__":
    sys.exit(main())
