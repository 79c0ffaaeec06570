"""``lft live``: the page in a real browser (Debian's chromium, headless, through Selenium) and the session's
edits. The browser test skips where chromium or its driver is missing; the set-up (scripts/bootstrap.sh)
installs both, so CI runs it."""

from __future__ import annotations

import base64
import shutil
import socket
import threading
import time

import numpy as np
import pytest

from lftransfer.app.pipeline import quick_scene
from lftransfer.scenes import builtin_scene, load_scene, with_overrides

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
DRIVER = shutil.which("chromedriver")


def _tiny_scene():
    """fig4 at an eighth of the paper's resolution, 8 x 8 directions, the point lighting model and one sample per
    pixel: frames of a few tenths of a second, the page is what is tested."""
    scene = quick_scene(load_scene(builtin_scene("fig4")))
    return with_overrides(scene, view={"resolution": [128, 96]}, render={"lighting_model": "point", "spp": 1},
                          rig={"lf_camera": [256, 192], "projector": [256, 192], "angular_samples": 8})


@pytest.fixture(scope="module")
def session(variant, tmp_path_factory):
    from lftransfer.app.viewer.command import open_session

    return open_session(_tiny_scene(), rig_model="oracle", truth_seed=None, out=tmp_path_factory.mktemp("live"))


def test_01_edits_are_checked_before_the_loop_sees_them(session):
    """NaN, a roughness on a diffuse object, values out of range and an object pushed out of its half-space are
    refused with a message naming the field; a good edit is queued."""
    from lftransfer.app.viewer.session import EditError

    good = {"type": "object", "side": "synthetic", "index": 0, "translate": [0.01, 0.0, -0.08]}
    assert session.submit(good) == {"type": "ack", "edit": "object"}
    bad = [({**good, "translate": [float("nan"), 0.0, -0.08]}, "translate\\[0\\]: expected a finite number"),
           ({**good, "translate": ["x", 0.0, -0.08]}, "translate\\[0\\]: expected a number"),
           ({**good, "roughness": 0.5}, "roughness: a diffuse material has no roughness"),
           ({**good, "albedo": [0.5, 2.0, 0.5]}, "albedo\\[1\\]: 2 is outside \\[0, 1\\]"),
           ({**good, "translate": [0.0, 0.0, 0.02]}, "must lie in z < 0"),
           ({**good, "index": 7}, "index: expected 0..0"),
           ({"type": "exchanges", "exchanges": 99}, "exchanges: 99 is outside"),
           ({"type": "lighting_model", "lighting_model": "magic"}, "lighting_model: expected one of"),
           ({"type": "warp"}, "unknown edit type")]
    for payload, message in bad:
        with pytest.raises(EditError, match=message):
            session.submit(payload)


def test_02_saved_scene_reads_back(session, tmp_path):
    from lftransfer.app.viewer.session import scene_toml

    path = tmp_path / "saved.toml"
    path.write_text(scene_toml(session.scene))
    back = load_scene(path)
    assert back.synthetic[0].translate == session.scene.synthetic[0].translate
    assert back.real[0].material == session.scene.real[0].material


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _pixels(data_url: str) -> np.ndarray:
    import cv2

    raw = base64.b64decode(data_url.split(",", 1)[1])
    return cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_COLOR).astype(np.float64)


@pytest.mark.skipif(CHROMIUM is None or DRIVER is None, reason="Debian's chromium and chromium-driver are not installed")
def test_03_page_in_a_real_browser(variant, tmp_path):
    """The page loads without console errors, shows a composite that is not black, a slider move changes the
    composite within 2 s, a bad value shows a message and the loop keeps running; a second tab watches too and
    closing it does not stop the loop."""
    import uvicorn
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.common.by import By

    from lftransfer.app.viewer.command import open_session
    from lftransfer.app.viewer.server import make_app

    session = open_session(_tiny_scene(), rig_model="oracle", truth_seed=None, out=tmp_path)
    port = _free_port()
    server = uvicorn.Server(uvicorn.Config(make_app(session), host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage"):
        options.add_argument(arg)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(DRIVER), options=options)
    try:
        deadline = time.time() + 60
        while not server.started and time.time() < deadline:
            time.sleep(0.1)
        driver.get(f"http://127.0.0.1:{port}/")

        def frame_src(timeout: float, other_than: str | None = None) -> str:
            end = time.time() + timeout
            while time.time() < end:
                src = driver.find_element(By.ID, "frame").get_attribute("src") or ""
                if src.startswith("data:image") and src != other_than:
                    return src
                time.sleep(0.05)
            raise AssertionError(f"no new frame within {timeout} s")

        first = frame_src(60)
        assert _pixels(first).max() > 40                                   # not black
        before = _pixels(frame_src(10, first))
        slider = driver.find_element(By.CSS_SELECTOR, 'fieldset.object[data-side="synthetic"] input.pose[data-key="translate"][data-axis="1"]')
        driver.execute_script("arguments[0].value = Number(arguments[0].value) + 0.04;"
                              "arguments[0].dispatchEvent(new Event('input'));", slider)
        t0 = time.time()
        changed = False
        while time.time() - t0 < 2.0 and not changed:
            now = _pixels(frame_src(2.0, None))
            changed = np.abs(now - before).mean() > 1.0
            time.sleep(0.05)
        assert changed, "the composite did not change within 2 s of moving the slider"
        typed = driver.find_element(By.CSS_SELECTOR, 'fieldset.object[data-side="synthetic"] input.typed[data-key="albedo"][data-axis="0"]')
        typed.clear()
        typed.send_keys("1.7\n")
        driver.execute_script("arguments[0].dispatchEvent(new Event('change'));", typed)
        end = time.time() + 5
        while time.time() < end and "outside" not in driver.find_element(By.ID, "message").text:
            time.sleep(0.05)
        assert "albedo[0]: 1.7 is outside [0, 1]" in driver.find_element(By.ID, "message").text
        latest = frame_src(1.0)
        frame_src(10, latest)                                              # the loop goes on
        driver.switch_to.new_window("tab")
        driver.get(f"http://127.0.0.1:{port}/")
        frame_src(30)
        driver.close()
        driver.switch_to.window(driver.window_handles[0])
        latest = frame_src(1.0)
        frame_src(10, latest)
        errors = [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
        assert not errors, errors
    finally:
        driver.quit()
        server.should_exit = True
        thread.join(30)
    assert not thread.is_alive() and session._thread is not None and not session._thread.is_alive()


def test_04_ground_truth_beside_the_composite(session):
    """On the simulated rig the "ground truth" layer shows the composite beside a path-traced ground truth of
    the state as it stands (rendered on its own thread; black until the first one is done)."""
    frame = session.live.step(0.0)
    session.scale = 1.0
    first = session._layer(frame, "ground truth")
    h, w = frame.composite.shape[:2]
    assert first.shape == (h, 2 * w, 3)
    session._gt_thread.join(120)
    side = session._layer(frame, "ground truth")[:, w:]
    assert side.max() > 0
