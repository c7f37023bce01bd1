"""Drives the served dataset browser in headless Chromium (tests/browser.rs runs it).

argv: base URL, expected counts (JSON), a clip id with a mirror, screenshot folder.
The expected JSON also names a synthetic pair to open by its address (`#clip=<id>`) with its own
frame count, a motion-type search with its count, and the table's columns and rows for the
column view.
Prints a JSON summary; any failed check raises, so the process exits non-zero.
"""
import json
import os
import shutil
import sys
import tempfile
import time
import urllib.parse

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
    # Before a clip is chosen: a hint, not an empty canvas.
    hint = driver.execute_script(
        "return [getComputedStyle(document.getElementById('player-hint')).display,"
        " getComputedStyle(document.getElementById('player')).display,"
        " document.getElementById('player-hint').textContent]"
    )
    assert hint[0] != "none" and hint[1] == "none" and "Choose a clip" in hint[2], hint
    summary["hint"] = hint[2].split(".")[0]
    driver.save_screenshot(os.path.join(shots, "browser-hint.png"))
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
    # The report rendered: its tables are tables, its figures inline with their captions, no
    # Markdown left as text.
    report = driver.execute_script(
        "const b = document.getElementById('report-body');"
        "return {tables: b.querySelectorAll('table').length,"
        " figures: b.querySelectorAll('figure img').length,"
        " captions: [...b.querySelectorAll('figure figcaption')].map(c => c.textContent),"
        " right: b.querySelectorAll('td.right').length,"
        " raw: b.textContent.includes('|---') || b.textContent.includes('![') || b.querySelectorAll('pre').length}"
    )
    assert report["tables"] >= expected["report"]["tables"], report
    assert report["figures"] == expected["report"]["figures"], report
    assert len(report["captions"]) == report["figures"], report
    assert all(len(c.strip()) > 5 for c in report["captions"]), report
    assert report["right"] > 0 and not report["raw"], report
    summary["report"] = {k: report[k] for k in ["tables", "figures", "right"]}
    driver.execute_script("document.querySelector('#report-body figure').scrollIntoView()")
    driver.save_screenshot(os.path.join(shots, "browser-report.png"))
    driver.execute_script("window.scrollTo(0, 0)")
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
    # A motion type is searched as text is.
    box.send_keys(expected["type_search"][0])
    settle(expected["type_search"][1], f"search={expected['type_search'][0]}")
    types = driver.execute_script("return window.playerState.clips.map(c => c.motion_type)")
    assert all(expected["type_search"][0] in (t or "") for t in types), types
    box.clear()
    driver.execute_script(
        "document.getElementById('filter-text').dispatchEvent(new Event('input'))"
    )
    settle(expected["all"], "all after search")

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
    # Choosing a clip gives the page its address.
    address = driver.execute_script("return location.hash")
    assert address.startswith("#clip="), address
    assert driver.execute_script("return decodeURIComponent(location.hash.slice(6))") == clip, address
    summary["address"] = address

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

    # A synthetic pair opened by its address: its sources beside it, headed as sources (a
    # mirrored one "mirrored source"), whole ids in the titles, and its own frame count.
    pair = expected["pair"]
    driver.get("about:blank")
    driver.get(base + "/#clip=" + urllib.parse.quote(pair["id"], safe=""))
    try:
        wait.until(
            lambda d: d.execute_script(
                "const s = window.playerState; return s.panels.length === 3 &&"
                " s.panels.every(p => p.drawn > 0 && p.title)"
            )
        )
    except Exception:
        raise AssertionError("the pair's address did not open it with its two sources")
    opened = driver.execute_script(
        "const s = window.playerState;"
        "return {ids: s.panels.map(p => p.motion.clip_id), headings: s.panels.map(p => p.title.heading),"
        " idLines: s.panels.map(p => p.title.idLines.join('')),"
        " scrub: Number(document.getElementById('scrub').max),"
        " label: document.getElementById('frame-label').textContent}"
    )
    assert opened["ids"] == [pair["id"]] + pair["sources"], opened
    assert opened["idLines"] == opened["ids"], opened
    assert opened["headings"] == pair["headings"], opened
    assert opened["scrub"] == pair["frames"] - 1, opened
    assert opened["label"] == f"1 / {pair['frames']}", opened
    summary["pair"] = opened
    driver.save_screenshot(os.path.join(shots, "browser-pair.png"))

    # The column view: every column with its statistics, the rows a page at a time.
    table = expected["table"]

    def table_state():
        return driver.execute_script(
            "const t = document.getElementById('columns-table');"
            "return {offset: Number(t.dataset.offset), total: Number(t.dataset.total),"
            " rows: t.tBodies[0].rows.length,"
            " names: [...t.tHead.rows[0].cells].map(c => c.firstChild.textContent),"
            " stats: Object.fromEntries([...t.tHead.rows[1].cells].map(c => [c.dataset.column, c.textContent])),"
            " first: t.tBodies[0].rows.length ? t.tBodies[0].rows[0].cells[0].textContent : null,"
            " range: document.getElementById('rows-range').textContent}"
        )

    try:
        wait.until(lambda d: table_state()["total"] == table["total"])
    except Exception:
        raise AssertionError(f"the column view shows {table_state()}")
    first = table_state()
    assert first["names"] == table["columns"], first["names"]
    assert first["rows"] == min(20, table["total"]) and first["offset"] == 0, first
    assert first["first"] == table["first_id"], first
    for column, words in table["stats"].items():
        for word in words:
            assert word in first["stats"][column], (column, word, first["stats"][column])
    driver.execute_script("document.getElementById('table-view').scrollIntoView()")
    driver.save_screenshot(os.path.join(shots, "browser-table.png"))
    driver.find_element(By.ID, "rows-next").click()
    try:
        wait.until(lambda d: table_state()["offset"] == 20)
    except Exception:
        raise AssertionError(f"Next did not page: {table_state()}")
    second = table_state()
    assert second["rows"] == min(20, table["total"] - 20), second
    assert second["first"] == table["id_at_20"], second
    summary["table"] = {"columns": len(first["names"]), "pages": [first["range"], second["range"]]}
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
