"""The viewer in a real browser: headless Chromium (Debian's) driven by Playwright.

Skipped when no Chromium is installed, unless TRACKER_REQUIRE_BROWSER is set (CI sets it).
"""

import os
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from tracker.io.posefile import load_pose_file
from tracker.io.poses import load_poses
from tracker.io.recording import open_recording
from tracker.model import load_model
from tracker.tracking.frame_loop import Tracker
from tracker.viewer.placement import Placement
from tracker.viewer.review import Review
from tracker.viewer.scene import BODY, Scene

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "recordings" / "demo"
CHROMIUM = os.environ.get("CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")
FLAGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]

if CHROMIUM is None and os.environ.get("TRACKER_REQUIRE_BROWSER"):
    pytest.fail("no Chromium found: install Debian's chromium package or set CHROMIUM", pytrace=False)
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="no Chromium installed")


@pytest.fixture
def page():
    playwright = pytest.importorskip("playwright.sync_api")
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=FLAGS)
        yield browser.new_page(viewport={"width": 1400, "height": 900})
        browser.close()


def _open(page, server, cameras: int) -> None:
    page.goto(f"http://127.0.0.1:{server.get_port()}")
    page.wait_for_selector("canvas", timeout=60_000)
    # every camera panel has received a decoded image
    page.wait_for_function(
        f"() => [...document.querySelectorAll('img')].filter("
        f"i => i.complete && i.naturalWidth >= 320).length >= {cameras}",
        timeout=60_000,
    )


def _body_pixels(rgb: np.ndarray) -> int:
    """Pixels with the body's orange hue (shaded lighter or darker)."""
    hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)
    target = cv2.cvtColor(np.uint8([[BODY]]), cv2.COLOR_RGB2HSV)[0, 0]
    return int(
        ((np.abs(hsv[..., 0].astype(int) - int(target[0])) <= 6) & (hsv[..., 1] > 120) & (hsv[..., 2] > 60)).sum()
    )


def test_viewer_draws_the_body_and_the_camera_images(server, page, tmp_path, tracked_demo):
    rec = open_recording(DEMO)
    model = load_model(rec.model_path)
    truth = load_poses(rec.truth_path)
    scene = Scene(server, model, rec.cameras, truth_names=list(truth["joint_names"]))
    review = Review(scene, rec, Tracker(model, rec.cameras, tracked_demo["poses"][0]), tracked_demo, truth)
    try:
        review.show(40)
        _open(page, server, 3)
        page.wait_for_timeout(3000)  # let the renderer settle on the body (a bounded wait, not a sleep in Python)
        shot = tmp_path / "viewer.png"
        page.screenshot(path=str(shot))
        rgb = cv2.cvtColor(cv2.imread(str(shot)), cv2.COLOR_BGR2RGB)
        assert _body_pixels(rgb[:, :1000]) > 800, f"no body drawn in the 3-D view; see {shot}"
        panels = [img for img in page.query_selector_all("img") if (img.bounding_box() or {}).get("width", 0) > 200]
        assert len(panels) >= 3
        for img in panels[:3]:
            data = np.frombuffer(img.screenshot(), np.uint8)
            panel = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE)
            assert panel.std() > 20, "a camera panel is blank"
        if os.environ.get("TRACKER_SCREENSHOT"):
            shutil.copy(shot, os.environ["TRACKER_SCREENSHOT"])
    finally:
        review.close()


def test_init_buttons_work_from_the_browser(server, page, tiny_recording, tmp_path):
    rec = open_recording(tiny_recording)
    model = load_model(rec.model_path)
    start = load_pose_file(rec.init_path, model)
    start[:, 0:3, 3] += [0.04, 0.0, 0.0]
    out = tmp_path / "init.toml"
    placement = Placement(Scene(server, model, rec.cameras), rec, model, start, out)
    _open(page, server, 2)
    page.get_by_role("button", name="Snap to the images").click()
    page.wait_for_function("() => document.body.innerText.includes('Snapped')", timeout=60_000)
    page.get_by_role("button", name="Save init.toml").click()
    assert placement.saved.wait(timeout=60)
    saved = load_pose_file(out, model)
    assert np.abs(saved[0, 0:3, 3] - start[0, 0:3, 3]).max() > 0.01  # snapping moved it before saving


def test_recorded_session_plays_in_viser_static_client(server, page, tracked, tmp_path):
    import functools
    import http.server
    import threading

    import viser

    recording, results = tracked
    rec = open_recording(recording)
    model = load_model(rec.model_path)
    review = Review(Scene(server, model, rec.cameras), rec, Tracker(model, rec.cameras, results["poses"][0]), results)
    site = tmp_path / "site"
    shutil.copytree(Path(viser.__file__).parent / "client" / "build", site)
    try:
        review.record(site / "session.viser", progress=False)
    finally:
        review.close()
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(site))
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    try:
        page.goto(f"http://127.0.0.1:{httpd.server_address[1]}/?playbackPath=/session.viser")
        page.wait_for_selector("canvas", timeout=60_000)
        page.wait_for_timeout(3000)
        shot = tmp_path / "playback.png"
        page.screenshot(path=str(shot))
        rgb = cv2.cvtColor(cv2.imread(str(shot)), cv2.COLOR_BGR2RGB)
        assert _body_pixels(rgb) > 300, f"the recorded body is not drawn; see {shot}"
    finally:
        httpd.shutdown()
