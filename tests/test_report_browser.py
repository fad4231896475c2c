"""The report in a real headless browser (Debian's chromium driven by Playwright).

Run directly to save a screenshot for the docs:
    uv run python tests/test_report_browser.py docs/report.png [RESULT_DIR]
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

import physpose.report as report
from physpose.report import build_report

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]
VIEWPORT = {"width": 1280, "height": 1000}


def _skip_reason() -> str | None:
    if not CHROMIUM.is_file():
        return f"{CHROMIUM} not installed (apt-get install chromium; CI installs it)"
    if not report.BUNDLE.is_file():
        return "viewer bundle not built; run `make setup`"
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "playwright (dev dependency) not installed; run `uv sync`"
    return None


def open_report(playwright, html: Path):
    """Launch chromium on a report; returns (browser, page, console errors list)."""
    browser = playwright.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
    page = browser.new_page(viewport=VIEWPORT)
    errors: list[str] = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.on("requestfailed", lambda r: errors.append(f"request failed: {r.url}"))
    page.goto(html.as_uri())
    page.wait_for_function("window.physposeViewer !== undefined", timeout=20_000)
    return browser, page, errors


def _canvas_variance(page) -> float:
    import cv2

    png = page.locator("#view").screenshot()
    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_GRAYSCALE)
    return float(img.astype(float).var())


@pytest.fixture(scope="module")
def browser_page(tmp_path_factory):
    reason = _skip_reason()
    if reason:
        pytest.skip(reason)
    from playwright.sync_api import sync_playwright
    from synthetic_result import save_result

    html = build_report(save_result(tmp_path_factory.mktemp("report"), num_frames=50))
    with sync_playwright() as pw:
        browser, page, errors = open_report(pw, html)
        yield page, errors
        browser.close()


def test_page_loads_without_console_errors(browser_page):
    page, errors = browser_page
    page.wait_for_timeout(300)
    assert errors == []
    assert page.locator("#plots canvas").count() == 5  # feet, com, gap, grf, losses


def test_canvas_shows_the_scene(browser_page):
    page, _ = browser_page
    assert _canvas_variance(page) > 20.0  # a blank canvas has variance 0


def test_play_advances_and_pause_stops_the_frame_counter(browser_page):
    page, _ = browser_page
    start = int(page.inner_text("#frame"))
    page.click("#play")
    page.wait_for_function(f"Number(document.getElementById('frame').textContent) > {start + 2}",
                           timeout=10_000)
    page.click("#play")  # pause
    held = page.inner_text("#frame")
    page.wait_for_timeout(400)
    assert page.inner_text("#frame") == held
    assert page.get_attribute("#play", "aria-pressed") == "false"


def test_scrub_and_motion_toggle_change_the_view(browser_page):
    page, errors = browser_page
    page.locator("#scrub").fill("10")
    assert page.inner_text("#frame") == "11"
    before = page.locator("#view").screenshot()
    page.check("input[value=kinematic]")
    page.wait_for_timeout(200)
    assert page.locator("#view").screenshot() != before
    assert errors == []


def save_screenshot(out: Path, result_dir: Path | None = None) -> Path:
    """Screenshot of a report (of result_dir, or of a synthetic result) for the docs."""
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory() as tmp:
        if result_dir is None:
            sys.path.insert(0, str(Path(__file__).parent))
            from synthetic_result import save_result
            result_dir = save_result(Path(tmp), num_frames=75)
        html = build_report(result_dir, Path(tmp) / "report.html")
        with sync_playwright() as pw:
            browser, page, errors = open_report(pw, html)
            page.locator("#scrub").fill("30")
            page.check("input[value=both]")
            page.wait_for_timeout(500)
            out.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(out), full_page=True)
            browser.close()
    if errors:
        raise RuntimeError(f"console errors: {errors}")
    return out


if __name__ == "__main__":
    print(save_screenshot(Path(sys.argv[1]), Path(sys.argv[2]) if len(sys.argv) > 2 else None))
