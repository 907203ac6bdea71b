#!/usr/bin/env python3
"""The dashboard in a real browser (issue 15): Debian's Chromium driven by
its packaged chromedriver through Selenium, offline.

    browser_check.py URL TOKEN

Opens the queue, submits two draft compares and a tune through the API,
watches a run page update to `succeeded` by itself, opens compare for the
two runs, cancels a running map from its page with the token entered in the
page, and screenshots each page. Each screenshot (ids and times hidden) is
checked against `.ci/browser/<page>.png` within a tolerance; any console
error fails. ZWIDTH_UPDATE_BASELINES=1 writes the baselines instead;
ZWIDTH_DOCS_SHOTS=DIR also writes unmasked screenshots there (docs/ui).
Prints `browser: N passed`.
"""
import json
import os
import shutil
import sys
import tempfile
import time
import urllib.request

os.environ.setdefault("SE_OFFLINE", "true")  # Selenium Manager: no downloads
from PIL import Image, ImageChops  # noqa: E402
from selenium import webdriver  # noqa: E402
from selenium.webdriver.chrome.service import Service  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402

URL, TOKEN = sys.argv[1].rstrip("/"), sys.argv[2]
HERE = os.path.dirname(os.path.abspath(__file__))
BASE = os.path.join(HERE, "browser")
UPDATE = os.environ.get("ZWIDTH_UPDATE_BASELINES") == "1"
DOCS = os.environ.get("ZWIDTH_DOCS_SHOTS")
# A pixel differs when a channel moves by more than 48 of 255; a page may
# differ in at most 0.25 % of its pixels (anti-aliasing, a font hinting change;
# runs on one machine differ in none).
PIXEL, SHARE = 48, 0.0025
WIDTH = 1280
passed = 0
errors = []


def check(cond, what):
    global passed
    if cond:
        passed += 1
    else:
        errors.append(what)
        print("FAIL:", what, flush=True)


def api(method, path, body=None):
    req = urllib.request.Request(URL + path, method=method)
    req.add_header("Authorization", "Bearer " + TOKEN)
    data = None
    if body is not None:
        data = json.dumps(body).encode()
        req.add_header("Content-Type", "application/json")
    with urllib.request.urlopen(req, data, timeout=30) as r:
        return json.loads(r.read() or b"null")


def wait(what, secs, cond):
    end = time.time() + secs
    while time.time() < end:
        try:
            v = cond()
            if v:
                return v
        except Exception:  # an element not there yet
            pass
        time.sleep(0.2)
    raise SystemExit(f"timed out after {secs} s waiting for {what}")


def state(i):
    return api("GET", f"/v1/experiments/{i}")["state"]


opts = webdriver.ChromeOptions()
opts.binary_location = "/usr/bin/chromium"
profile = tempfile.mkdtemp(prefix="zwidth-chromium-")
for a in ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
          "--disable-background-networking", "--disable-component-update", "--disable-sync",
          "--hide-scrollbars", "--force-device-scale-factor=1", "--font-render-hinting=none",
          f"--window-size={WIDTH},1000", f"--user-data-dir={profile}"]:
    opts.add_argument(a)
opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
drv = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=opts)


def console():
    """Console errors since the last call (a page's own or a failed load)."""
    bad = [e for e in drv.get_log("browser") if e.get("level") == "SEVERE"]
    for e in bad:
        print("console error:", e.get("message"), flush=True)
    return bad


def shot(name):
    """Screenshot the whole page: unmasked for the docs, masked (ids,
    times, progress hidden) against the baseline."""
    h = drv.execute_script("return Math.min(4000, document.documentElement.scrollHeight)")
    drv.execute_cdp_cmd("Emulation.setDeviceMetricsOverride",
                        {"width": WIDTH, "height": h, "deviceScaleFactor": 1, "mobile": False})
    time.sleep(0.3)
    if DOCS:
        os.makedirs(DOCS, exist_ok=True)
        drv.save_screenshot(os.path.join(DOCS, f"{name}.png"))
    # The live part stops polling (so nothing is redrawn under the mask);
    # what changes from run to run (ids, times, progress, the token's
    # state) becomes one fixed, hidden text, so the layout does not move.
    # (Through the CSSOM: the pages' CSP allows no injected style sheet.)
    drv.execute_script(
        "document.body.addEventListener('htmx:beforeRequest', function (e) { e.preventDefault(); });"
        "document.querySelectorAll('.volatile,.id,#token-state,#flash').forEach(function (e) {"
        "  e.textContent = 'xxxxxxxx'; e.style.visibility = 'hidden'; });")
    time.sleep(0.2)
    got = os.path.join(tempfile.gettempdir(), f"zwidth-shot-{name}.png")
    drv.save_screenshot(got)
    drv.execute_cdp_cmd("Emulation.clearDeviceMetricsOverride", {})
    base = os.path.join(BASE, f"{name}.png")
    if UPDATE:
        os.makedirs(BASE, exist_ok=True)
        Image.open(got).convert("RGB").save(base, optimize=True)
        print(f"baseline written: {base}")
        return
    if not os.path.exists(base):
        check(False, f"no baseline {base} (ZWIDTH_UPDATE_BASELINES=1 writes it)")
        return
    a, b = Image.open(base).convert("RGB"), Image.open(got).convert("RGB")
    if a.size != b.size:
        check(False, f"{name}: {b.size} px, the baseline is {a.size} (kept at {got})")
        return
    diff = ImageChops.difference(a, b).convert("L").point(lambda v: 255 if v > PIXEL else 0)
    share = diff.histogram()[255] / (a.size[0] * a.size[1])
    print(f"{name}: {100 * share:.3f} % of pixels differ from the baseline")
    check(share <= SHARE, f"{name}: {100 * share:.2f} % of pixels differ (at most {100 * SHARE} %; kept at {got})")


def badge():
    return drv.find_element(By.CSS_SELECTOR, "#live .badge").text


try:
    # 1. The queue opens (nothing submitted yet).
    drv.get(URL + "/")
    check(drv.find_element(By.TAG_NAME, "h1").text == "Queue", "the queue page")
    check(not console(), "no console error on the queue")

    # 2. Two draft compares and a fast tune through the API.
    a = api("POST", "/v1/experiments", {"kind": "compare", "accuracy": "draft"})["id"]
    b = api("POST", "/v1/experiments", {"kind": "compare", "accuracy": "draft"})["id"]
    linear = {"device": {"coulomb": 0, "quantization": 0}, "loop": {"sample_hz": 1000, "render_hz": 1000},
              "estimator": {"kind": "butterworth", "cutoff_hz": 200, "order": 2}}
    t = api("POST", "/v1/experiments", {"kind": "tune", "scene": linear, "params": {"cutoff_hz": [50, 450]},
                                        "objective": "k_width", "accuracy": "draft", "final_accuracy": "draft",
                                        "finalists": 2, "max_evaluations": 12, "b": [0, 20]})["id"]

    # 3. The run page updates by itself until the run succeeds: the second
    # compare's, which waits behind the first on the one rig.
    drv.get(f"{URL}/runs/{b}")
    first = badge()
    drv.execute_script("window.__same_page = 42;")
    check(first in ("queued", "running"), f"the run page opened before the run ended ({first})")
    wait("the run page to show succeeded", 300, lambda: badge() == "succeeded")
    check(drv.execute_script("return window.__same_page") == 42, "updated in place, not reloaded")
    drv.get(f"{URL}/runs/{a}")
    wait("the first compare's page", 30, lambda: badge() == "succeeded")
    maps = drv.find_elements(By.CSS_SELECTOR, "#live figure svg")
    check(len(maps) == 4, f"four maps, one per estimator ({len(maps)})")
    stored = api("GET", f"/v1/experiments/{a}")["progress"]["trials_done"]
    shown = drv.find_element(By.CSS_SELECTOR, "#live .trials").text
    check(shown == f"{stored} trials", f"trials shown {shown!r} = stored {stored}")
    check(not console(), "no console error on the run page")
    wait("the tune", 600, lambda: state(t) == "succeeded")

    # 4. A slow map runs (and one waits): cancel it from its page.
    seed = json.load(open(os.path.join(HERE, "..", "examples", "seed_2018.json")))
    slow = api("POST", "/v1/experiments", {"kind": "map", "scene": seed, "accuracy": "reference"})["id"]
    later = api("POST", "/v1/experiments", {"kind": "map", "scene": seed, "accuracy": "reference"})["id"]
    drv.get(URL + "/")
    wait("the slow map to run", 120, lambda: slow[-8:] in drv.find_element(By.CSS_SELECTOR, "table.running").text)
    wait("the waiting one listed", 30, lambda: later[-8:] in drv.find_element(By.CSS_SELECTOR, "table.waiting").text)
    shot("queue")
    drv.get(f"{URL}/runs/{slow}")
    wait("the slow map's page", 30, lambda: badge() == "running")
    drv.find_element(By.ID, "token").send_keys(TOKEN)
    drv.find_element(By.CSS_SELECTOR, "#token-form button[type=submit]").click()
    wait("the token saved", 10, lambda: drv.find_element(By.ID, "token-state").text == "token saved")
    # The live part is redrawn every 2 s: find and click in one go, again
    # if the button was replaced in between.
    wait("the cancel button clicked", 30, lambda: drv.find_element(
        By.CSS_SELECTOR, "#live button.action[data-url$='/cancel']").click() is None)
    wait("the page to show cancelled", 60, lambda: badge() == "cancelled")
    check(state(slow) == "cancelled", "the API says cancelled too")
    check(not console(), "no console error while cancelling")
    api("POST", f"/v1/experiments/{later}/cancel")
    wait("the waiting one cancelled", 30, lambda: state(later) == "cancelled")

    # 5. Each page's screenshot against its baseline.
    drv.get(f"{URL}/runs/{a}")
    wait("the run page", 10, lambda: badge() == "succeeded")
    shot("run")
    drv.get(f"{URL}/compare?runs={a},{b}")
    panels = drv.find_elements(By.CSS_SELECTOR, ".maps figure")
    check(len(panels) == 8, f"eight panels: two runs × four estimators ({len(panels)})")
    check("differences only" in drv.page_source.lower() or "specs are the same" in drv.page_source,
          "the spec differences")
    shot("compare")
    drv.get(f"{URL}/runs/{t}")
    check("against cutoff_hz" in drv.page_source, "the tune's landscape")
    shot("tune")
    drv.get(URL + "/runs")
    check(len(drv.find_elements(By.CSS_SELECTOR, "table.runs tbody tr")) == 5, "five runs listed")
    shot("runs")
    drv.get(URL + "/")
    shot("queue-idle")
    check(not console(), "no console error on any page")
finally:
    drv.quit()
    shutil.rmtree(profile, ignore_errors=True)

print(f"browser: {passed} passed, {len(errors)} failed")
sys.exit(1 if errors else 0)
