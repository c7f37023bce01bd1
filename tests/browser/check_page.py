"""Drives the served dataset browser in headless Chromium (tests/browser.rs runs it).

argv: base URL, expected counts (JSON), a clip id with a mirror, screenshot folder.
Prints a JSON summary; any failed check raises, so the process exits non-zero.
"""
import json
import os
import shutil
import sys
import tempfile
import time

from selenium import webdriver
from selenium.webdriver.chrome.options import Options
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import Select, WebDriverWait

base, expected_json, clip, shots = sys.argv[1:5]
expected = json.loads(expected_json)
os.makedirs(shots, exist_ok=True)

profile = tempfile.mkdtemp(prefix="motionforge-chromium-")
options = Options()
for arg in [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    f"--user-data-dir={profile}",
    "--window-size=1400,1200",
]:
    options.add_argument(arg)
# The console, to find Content-Security-Policy violations in it.
options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
options.binary_location = shutil.which("chromium") or shutil.which("chromium-browser")
driver = webdriver.Chrome(
    service=Service(shutil.which("chromedriver")), options=options
)
summary = {}
try:
    wait = WebDriverWait(driver, 30)
    driver.get(base + "/")

    def total():
        return driver.execute_script(
            "const e = document.getElementById('clip-count');"
            "return e.dataset.total === undefined ? null : Number(e.dataset.total);"
        )

    def settle(want, what):
        try:
            wait.until(lambda d: total() == want)
        except Exception:
            raise AssertionError(f"{what}: the list shows {total()} clips, expected {want}")
        # The list holds exactly the rows the count says (the page asks for up to 1000).
        rows = len(driver.find_elements(By.CSS_SELECTOR, "#clip-list li"))
        assert rows == want, f"{what}: {rows} rows listed, count says {want}"
        summary[what] = want

    settle(expected["all"], "all")
    # The page's own style sheet applies under the service's Content-Security-Policy (inline
    # style attributes would not), and the report's figures load from the service.
    styles = driver.execute_script(
        "const s = (q, p) => getComputedStyle(document.querySelector(q))[p];"
        "return [s('.legend i.left_arm', 'backgroundColor'), s('section.spaced', 'marginTop'),"
        " s('header', 'backgroundColor')]"
    )
    assert styles == ["rgb(31, 90, 220)", "12px", "rgb(38, 50, 56)"], styles
    summary["styles"] = styles
    try:
        wait.until(
            lambda d: d.execute_script(
                "const i = [...document.querySelectorAll('#report img')];"
                "i.forEach(x => x.loading = 'eager');"
                "return i.length > 0 && i.every(x => x.complete && x.naturalWidth > 0)"
            )
        )
    except Exception:
        raise AssertionError("the report's figures did not load")
    for select_id, value, want in expected["filters"]:
        Select(driver.find_element(By.ID, select_id)).select_by_value(value)
        settle(want, f"{select_id}={value}")
        Select(driver.find_element(By.ID, select_id)).select_by_value("")
        settle(expected["all"], "all again")
    box = driver.find_element(By.ID, "filter-text")
    box.send_keys(expected["text"][0])
    settle(expected["text"][1], f"text={expected['text'][0]}")
    box.clear()
    driver.execute_script(
        "document.getElementById('filter-text').dispatchEvent(new Event('input'))"
    )
    settle(expected["all"], "all after text")

    # A clip with its mirror beside it.
    driver.find_element(By.CSS_SELECTOR, f"#clip-list li[data-id='{clip}']").click()
    wait.until(
        lambda d: d.execute_script(
            "return window.playerState.panels.length === 2 &&"
            " window.playerState.panels.every(p => p.drawn > 0)"
        )
    )
    ids = driver.execute_script(
        "return window.playerState.panels.map(p => [p.motion.clip_id, p.meta.mirrored, p.drawn])"
    )
    assert ids[0][0] == clip and not ids[0][1], ids
    assert ids[1][0] == clip + ":m" and ids[1][1], ids
    summary["panels"] = ids

    ink = """
      const c = document.getElementById('player');
      const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
      let left = 0, right = 0;
      for (let i = 0; i < d.length; i += 4) {
        // Bone colours: saturated pixels, not the grey grid or the black text.
        const mx = Math.max(d[i], d[i+1], d[i+2]), mn = Math.min(d[i], d[i+1], d[i+2]);
        if (mx - mn > 80) { if (((i / 4) % c.width) < c.width / 2) left++; else right++; }
      }
      return [left, right, c.toDataURL()];
    """
    left, right, before = driver.execute_script(ink)
    assert left > 150 and right > 150, f"coloured pixels: {left} left, {right} right"
    summary["coloured_pixels_before"] = [left, right]
    driver.save_screenshot(os.path.join(shots, "browser-paused.png"))

    driver.find_element(By.ID, "play").click()
    time.sleep(1.5)
    frame = driver.execute_script("return window.playerState.frame")
    left2, right2, after = driver.execute_script(ink)
    assert frame > 0, f"still at frame {frame} after playing"
    assert after != before, "the canvas did not change while playing"
    assert left2 > 150 and right2 > 150, f"coloured pixels while playing: {left2}, {right2}"
    summary["frame_after_play"] = frame
    driver.save_screenshot(os.path.join(shots, "browser-playing.png"))
    driver.find_element(By.ID, "play").click()
    blocked = [
        e["message"]
        for e in driver.get_log("browser")
        if "Content Security Policy" in e["message"] or "Content-Security-Policy" in e["message"]
    ]
    assert not blocked, f"the page broke its own Content-Security-Policy: {blocked}"
finally:
    driver.quit()
    shutil.rmtree(profile, ignore_errors=True)
print(json.dumps(summary))
