"""jaxmatch label in a real browser: Debian's headless Chromium driven by Playwright for Python.

The server is the real command (``python -m jaxmatch label ... --port 0``) in a subprocess; the
browser is /usr/bin/chromium (``scripts/test`` installs the Debian package when missing; no
``playwright install``, no browser download). Takes the screenshot (docs/label-page.png with
JAXMATCH_UPDATE_SCREENSHOT=1).
"""

import json
import os
import queue
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = "/usr/bin/chromium"
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
        "--disable-sync", "--no-first-run"]
README_SCREENSHOT = ROOT / "docs" / "label-page.png"
"""Rewritten by the test only with JAXMATCH_UPDATE_SCREENSHOT=1 (a test run leaves the tree as it was)."""

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} is missing (Debian package 'chromium'; scripts/test installs it)"),
]


@pytest.fixture
def server(tmp_path):
    """``(url, labels path)`` of a running ``jaxmatch label`` on a free port; stopped afterwards."""
    labels = tmp_path / "labels.jsonl"
    env = dict(os.environ, JAXMATCH_CACHE=str(tmp_path / "cache"), JAX_PLATFORMS="cpu", JAXMATCH_PROGRESS="0")
    proc = subprocess.Popen(
        [sys.executable, "-m", "jaxmatch", "label", str(ROOT / "examples" / "lshape.json"), str(ROOT / "examples" / "tshape.json"),
         "--labels", str(labels), "--internal", "2", "--top", "3", "--port", "0", "--epochs", "1"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path, env=env)
    lines: queue.Queue = queue.Queue()
    threading.Thread(target=lambda: [lines.put(x) for x in proc.stdout], daemon=True).start()
    try:
        try:
            url = lines.get(timeout=120).strip()
        except queue.Empty:
            raise AssertionError("the server printed no address in 120 s") from None
        assert url.startswith("http://127.0.0.1:") and url.endswith("/"), url
        yield url, labels
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        err = proc.stderr.read()
        assert "Traceback" not in err, err


def _labels(path):
    return [json.loads(x) for x in Path(path).read_text().splitlines() if x.strip() and not x.startswith("#")]


def test_label_page_in_chromium(server):
    from playwright.sync_api import expect, sync_playwright

    url, labels = server
    t0 = time.perf_counter()
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS, headless=True)
        try:
            page = browser.new_page(viewport={"width": 1280, "height": 860})
            errors = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(url)
            expect(page.locator("#progress")).to_have_text("labelled 0 / 2", timeout=60_000)
            cands = page.locator("#candidates .cand[data-mesh-id]")
            expect(cands).to_have_count(3, timeout=60_000)
            expect(page.locator("#shape-name")).to_contain_text("lshape.json")
            assert page.locator("#candidates .cand svg circle.bv").count() > 0  # boundary vertices by valence

            # click the second candidate: it is saved, the page moves on
            chosen = cands.nth(1).get_attribute("data-mesh-id")
            cands.nth(1).click()
            expect(page.locator("#msg")).to_contain_text(f"saved: {chosen}")
            expect(page.locator("#progress")).to_have_text("labelled 1 / 2")
            rec = _labels(labels)
            assert [r["preferred"] for r in rec] == [chosen] and rec[0]["shape"].endswith("examples/lshape.json")

            # the T shape by key 1
            expect(page.locator("#shape-name")).to_contain_text("tshape.json")
            expect(cands).to_have_count(3)
            first = cands.nth(0).get_attribute("data-mesh-id")
            page.keyboard.press("1")
            expect(page.locator("#progress")).to_have_text("labelled 2 / 2")
            assert [r["preferred"] for r in _labels(labels)] == [chosen, first]

            # draw a square: four clicks, close on the first point, use it
            page.click("#draw")
            box = page.locator("#draw-svg").bounding_box()
            corners = [(0.2, 0.8), (0.8, 0.8), (0.8, 0.2), (0.2, 0.2), (0.2, 0.8)]
            for fx, fy in corners:
                page.mouse.click(box["x"] + fx * box["width"], box["y"] + fy * box["height"])
            expect(page.locator("#draw-status")).to_contain_text("closed loop of 4 points")
            page.click("#draw-use")
            expect(page.locator("#shape-name")).to_contain_text("drawn shape", timeout=60_000)
            expect(cands).to_have_count(3, timeout=60_000)
            expect(page.locator("#progress")).to_have_text("labelled 2 / 3")
            square = cands.nth(0).get_attribute("data-mesh-id")
            cands.nth(0).click()
            expect(page.locator("#progress")).to_have_text("labelled 3 / 3")
            last = _labels(labels)[-1]
            assert last["preferred"] == square and len(last["shape"]["boundary"]) == 4

            # a bad drawn shape: the checks' message is shown
            page.click("#draw")
            for fx, fy in [(0.2, 0.2), (0.8, 0.8), (0.8, 0.2), (0.2, 0.8), (0.2, 0.2)]:
                page.mouse.click(box["x"] + fx * box["width"], box["y"] + fy * box["height"])
            page.click("#draw-use")
            expect(page.locator("#msg")).to_contain_text("crosses or touches itself")
            page.click("#draw-cancel")

            # a shape file dropped on the page (its bytes are sent; the server opens no path)
            text = (ROOT / "examples" / "hexagon.json").read_text()
            dt = page.evaluate_handle("(t) => { const d = new DataTransfer(); d.items.add(new File([t], 'hexagon.json')); return d; }", text)
            page.dispatch_event("body", "drop", {"dataTransfer": dt})
            expect(page.locator("#shape-name")).to_contain_text("hexagon.json", timeout=60_000)
            expect(cands).to_have_count(3, timeout=60_000)
            expect(page.locator("#progress")).to_have_text("labelled 3 / 4")

            # back on the L shape: its label is marked; the screenshot for the README
            page.locator("#shapes li", has_text="lshape.json").click()
            expect(page.locator("#candidates .cand.chosen")).to_have_attribute("data-mesh-id", chosen)
            expect(page.locator("#shape-mark")).to_contain_text(chosen)
            shot = README_SCREENSHOT if os.environ.get("JAXMATCH_UPDATE_SCREENSHOT") == "1" else Path(labels).parent / "label-page.png"
            page.screenshot(path=str(shot), full_page=True)
            assert shot.stat().st_size > 10_000

            # tune on the three labels: before/after shown, the lattice written beside the labels
            page.click("#tune")
            expect(page.locator("#tune-result table")).to_contain_text("held out", timeout=180_000)
            expect(page.locator("#tune-download")).to_have_attribute("download", "tuned.toml")
            assert labels.with_suffix(".tuned.toml").is_file()
            assert not errors, errors
        finally:
            browser.close()
    print(f"browser part: {time.perf_counter() - t0:.1f} s")
