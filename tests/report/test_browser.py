"""Reports opened in a real headless browser: Debian's ``chromium`` driven by Selenium through
Debian's ``chromedriver`` (no browser download; ``scripts/bootstrap.sh`` installs both).

For the report of a small run of each kind: no console error (nor a WebGL warning), every
``<img>`` decoded with a non-zero size, every figure the kind must show present, the 3D
canvas drawn (its WebGL buffer read back holds at least :data:`MIN_CLOUD_PIXELS` pixels
that are not the white background), and a screenshot of the whole page saved (to
``$VIRTUS_TEST_ARTIFACTS`` when set, else the test's temporary folder). With WebGL disabled
the still image takes the canvas's place, without a console error; with every host name
unresolvable the page still loads whole and asks for nothing.

Software WebGL needs ``--enable-unsafe-swiftshader`` on a machine without a GPU.
"""

from __future__ import annotations

import base64
import io
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from virtus.report import write_report

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"

pytestmark = pytest.mark.skipif(
    not (Path(CHROMIUM).is_file() and Path(CHROMEDRIVER).is_file()),
    reason="Debian's chromium and chromium-driver are not installed "
    "(scripts/bootstrap.sh installs them: apt-get install chromium chromium-driver)",
)

#: Flags of every browser the tests start (headless, software WebGL, nothing in the background).
FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--window-size=1400,1000",
)
#: Least number of non-background pixels of a drawn 3D view (the 160 px scans give 20,000+
#: points at 2 px each, the 64 px robot view ~4,000; an empty or failed canvas has none).
MIN_CLOUD_PIXELS = 500

#: Figures each kind's report must show (ids of ``figure``/3D blocks in the page).
EXPECTED = {
    "demo": (
        "fig-calibration-board-poses", "fig-calibration-per-pose-rms",
        "fig-calibration-coverage", "fig-calibration-residual-vectors",
        "fig-sphere-scan-frames-frame-phase", "fig-sphere-scan-frames-frame-gray",
        "fig-decode-wrapped-phase-v", "fig-decode-absolute-phase-v",
        "fig-decode-wrapped-phase-h", "fig-decode-modulation", "fig-decode-valid-and-flagged",
        "fig-sphere-fit-radial-error-map", "fig-sphere-fit-radial-error-histogram",
        "view-3d-view-cloud",
    ),
    "scan": (
        "fig-frames-frame-phase", "fig-frames-frame-white", "fig-decode-wrapped-phase-v",
        "fig-decode-absolute-phase-h", "fig-decode-modulation", "fig-decode-valid-and-flagged",
        "fig-sphere-fit-radial-error-map", "fig-sphere-fit-radial-error-histogram",
        "view-3d-view-cloud",
    ),
    "calibrate": (
        "fig-calibration-board-poses", "fig-calibration-per-pose-rms",
        "fig-calibration-coverage", "fig-calibration-residual-vectors",
    ),
    "ablation": ("fig-ablation-heat-map", "fig-ablation-bars-radius-error-mm"),
    "dataset": (
        "fig-gallery-sample-0-frame", "fig-gallery-sample-0-depth",
        "fig-gallery-sample-0-wrapped", "fig-gallery-sample-3-frame",
    ),
    "acceptance": (
        "fig-acceptance-figure-p-f", "fig-acceptance-figure-p-s", "fig-acceptance-figure-sd",
        "fig-acceptance-figure-f",
    ),
    "predict": (
        "fig-prediction-sigma-u-p", "fig-prediction-sigma-depth", "fig-prediction-sigma-point",
        "fig-prediction-mask",
    ),
    "design": ("fig-design-figures-sweep-sigma-depth-um-median-steps",),
    "robot-scan": (
        "fig-cloud-to-mesh-distance-kinematics-alone-c2m-histogram-0",
        "fig-first-view-000-decode-wrapped-phase-v", "view-3d-view-cloud",
    ),
    "learn": (
        "fig-training-loss", "fig-evaluation-store-all-sample-0-predicted-depth",
        "fig-evaluation-store-all-sample-0-error",
    ),
    "twin": (
        "fig-twin-validation-real-against-virtual-differences-0", "fig-twin-maps-pose-0-white",
        "fig-twin-maps-pose-0-proj-uv", "fig-twin-maps-pose-1-code",
    ),
}  # fmt: skip


def _browser(*extra: str) -> object:
    webdriver = pytest.importorskip("selenium.webdriver")
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in (*FLAGS, f"--user-data-dir={tempfile.mkdtemp(prefix='virtus-chromium-')}", *extra):
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)


@pytest.fixture(scope="module")
def browser() -> Iterator[object]:
    driver = _browser()
    yield driver
    driver.quit()


@pytest.fixture(scope="module")
def artifacts(tmp_path_factory) -> Path:
    where = os.environ.get("VIRTUS_TEST_ARTIFACTS")
    folder = Path(where) / "report-screenshots" if where else tmp_path_factory.mktemp("shots")
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def _open(driver, page: Path) -> None:
    driver.get_log("browser")  # drop what earlier pages logged
    driver.get(page.resolve().as_uri())
    driver.execute_script("return document.readyState")


def _problems(driver) -> list[str]:
    """Console errors, and WebGL's API errors (logged as warnings: "WebGL: INVALID_...");
    not the software driver's performance notes ("GPU stall due to ReadPixels", which the
    read-back of a canvas causes)."""
    return [entry["message"] for entry in driver.get_log("browser")
            if entry["level"] == "SEVERE" or "WebGL: " in entry["message"]]  # fmt: skip


def _screenshot(driver, folder: Path, name: str) -> Path:
    height = driver.execute_script("return document.documentElement.scrollHeight")
    driver.set_window_size(1400, min(int(height) + 50, 16000))
    path = folder / f"{name}.png"
    assert driver.save_screenshot(str(path))
    driver.set_window_size(1400, 1000)
    return path


def _cloud_pixels(driver, ident: str) -> int:
    """Non-white pixels of a 3D view's WebGL buffer, read back with ``toDataURL``."""
    from PIL import Image

    url = driver.execute_script(
        "return document.getElementById(arguments[0]).querySelector('canvas').toDataURL()", ident
    )
    image = np.asarray(Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))))
    return int((image[..., :3].min(axis=2) < 240).sum())


@pytest.mark.parametrize("kind", sorted(EXPECTED))
def test_report_opens_whole_in_a_browser(kind, request, browser, artifacts, tmp_path) -> None:
    run_dir = request.getfixturevalue(f"{kind.replace('-', '_')}_run")
    report = write_report(run_dir, tmp_path / f"{kind}.html")  # the session run stays as made
    assert report.kind == kind
    _open(browser, report.path)
    assert _problems(browser) == []
    images = browser.execute_script(
        "return Array.from(document.images).map(i => [i.complete, i.naturalWidth, i.alt])"
    )
    assert images and all(done and width > 0 for done, width, _ in images), images
    present = set(
        browser.execute_script(
            "return Array.from(document.querySelectorAll('[data-figure]')).map(e => e.id)"
        )
    )
    assert set(EXPECTED[kind]) <= present, sorted(set(EXPECTED[kind]) - present)
    assert present == set(report.figures)
    for ident in (i for i in report.figures if i.startswith("view-")):
        mode = browser.execute_script(
            "return document.getElementById(arguments[0]).getAttribute('data-mode')", ident
        )
        assert mode == "webgl"
        assert _cloud_pixels(browser, ident) >= MIN_CLOUD_PIXELS
    shot = _screenshot(browser, artifacts, f"report-{kind}")
    assert shot.stat().st_size > 10_000


def test_without_webgl_the_still_image_takes_the_views_place(scan_run, tmp_path, artifacts):
    report = write_report(scan_run, tmp_path / "report.html")
    driver = _browser("--disable-webgl", "--disable-3d-apis")
    try:
        _open(driver, report.path)
        assert _problems(driver) == []
        block = driver.find_element("id", "view-3d-view-cloud")
        assert block.get_attribute("data-mode") == "still"
        assert block.find_element("css selector", "img.virtus-still").is_displayed()
        assert not block.find_element("css selector", "canvas").is_displayed()
        width = driver.execute_script(
            "return arguments[0].querySelector('img.virtus-still').naturalWidth", block
        )
        assert width > 0
        _screenshot(driver, artifacts, "report-scan-no-webgl")
    finally:
        driver.quit()


def test_the_page_needs_no_network(scan_run, tmp_path) -> None:
    """Every host name unresolvable: the page still loads whole, and the browser's record of
    what it fetched holds the page alone (no script, style, font or image from anywhere)."""
    folder = tmp_path / "offline"
    folder.mkdir()
    report = write_report(scan_run, folder / "report.html")
    text = report.path.read_text()
    assert "http://" not in text and "https://" not in text and "//cdn" not in text
    shutil.copy(report.path, tmp_path / "alone.html")  # no run files beside it either
    driver = _browser("--host-resolver-rules=MAP * ~NOTFOUND")
    try:
        _open(driver, tmp_path / "alone.html")
        assert _problems(driver) == []
        resources = driver.execute_script(
            "return performance.getEntriesByType('resource').map(e => e.name)"
        )
        assert resources == []
        mode = driver.execute_script(
            "return document.querySelector('.virtus-cloud').getAttribute('data-mode')"
        )
        assert mode == "webgl"
    finally:
        driver.quit()
