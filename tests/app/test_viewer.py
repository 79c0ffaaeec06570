"""``lft live``: the page in a real browser (Debian's chromium, headless, through Selenium), the session's edits
and the bounce layers it computes on demand. The browser test skips where chromium or its driver is missing; the
set-up (scripts/bootstrap.sh) installs both, so CI runs it."""

from __future__ import annotations

import base64
import os
import re
import signal
import shutil
import socket
import threading
import time

import numpy as np
import pytest

from lftransfer.scenes import quick_scene
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

    session = open_session(_tiny_scene(), rig_model="oracle", truth_seed=None, out=tmp_path_factory.mktemp("live"))
    yield session
    session.close()


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
    composite within 2 s, a bad value shows a message and the loop keeps running; the "bounce layers" button
    shows each bounce's real and synthetic layers with their gains (not black) and the loop goes on; a second
    tab watches too and closing it does not stop the loop."""
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
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1400,1000"):
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
        # the image fills the space beside the controls (1400 x 1000 window), kept to its aspect
        size = driver.execute_script("const f = document.getElementById('frame'); "
                                     "return [f.clientWidth, f.clientHeight, window.innerWidth];")
        assert size[0] > 0.6 * (size[2] - 400) and size[1] > 400, size
        end = time.time() + 10
        while time.time() < end and "capture" not in driver.find_element(By.ID, "rates").text:
            time.sleep(0.05)
        assert "decoupled: capture" in driver.find_element(By.ID, "rates").text
        # the simulator renders in its own process, and the page says how much of the machine it takes
        end = time.time() + 30
        while time.time() < end and "the simulator's process" not in driver.find_element(By.ID, "rates").text:
            time.sleep(0.2)
        assert re.search(r"cores busy of \d+: this loop [\d.]+, the simulator's process [\d.]+ \(\d+ % of the "
                         r"machine\)", driver.find_element(By.ID, "rates").text)
        assert "in turns" not in driver.find_element(By.ID, "rates").text           # side by side by default
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
        assert driver.find_element(By.ID, "bounces").get_attribute("hidden") is not None
        driver.find_element(By.ID, "bounce_layers").click()                 # the bounce layers, on demand
        end = time.time() + 60
        while time.time() < end and "took" not in driver.find_element(By.ID, "bounces_status").text:
            time.sleep(0.05)
        assert "1 bounce at t = 0.00 s, took" in driver.find_element(By.ID, "bounces_status").text
        tiles = driver.find_elements(By.CSS_SELECTOR, "#bounce_grid figure")
        captions = [t.find_element(By.TAG_NAME, "figcaption").text for t in tiles]
        # real and synthetic layers of bounces 0 and 1, then the composite
        assert len(tiles) == 2 * 2 + 1, captions
        assert captions[0] == captions[2] == "direct x1" and captions[4] == "composite x1", captions
        assert captions[1].startswith("bounce 1 x") and captions[3].startswith("bounce 1 x"), captions
        for t in tiles:
            assert _pixels(t.find_element(By.TAG_NAME, "img").get_attribute("src")).max() > 40      # not black
        assert driver.find_element(By.ID, "bounce_layers").is_enabled()
        latest = frame_src(1.0)
        frame_src(10, latest)                                              # the live loop goes on afterwards
        driver.find_element(By.ID, "compare_btn").click()                    # A/B against the ground truth
        end = time.time() + 120
        while time.time() < end and "PSNR" not in driver.find_element(By.ID, "compare_status").text:
            time.sleep(0.1)
        assert "over the objects" in driver.find_element(By.ID, "compare_status").text
        a_src = driver.find_element(By.ID, "ab_a").get_attribute("src")
        driver.find_element(By.ID, "ab_diff").click()
        assert driver.find_element(By.ID, "ab_a").get_attribute("src") not in ("", a_src)   # the difference
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


def test_04b_the_depth_layer(session):
    """The "depth" layer shows the real depth the depth composite uses (orange) beside the synthetic render's
    (blue), nearer brighter on one scale, black where a side has none; with the over composite (this session) the
    real tile is black."""
    from lftransfer.app.viewer.session import depth_layer
    from lftransfer.real_depth import ViewDepth

    frame = session.live.step(0.0)
    h, w = frame.composite.shape[:2]
    image = session._layer(frame, "depth")
    assert image.shape == (h, 2 * w, 3) and image[:, :w].max() == 0
    covered = np.isfinite(frame.synthetic_view.depth)
    assert image[:, w:][covered, 2].min() > 0 and image[:, w:][~covered].max() == 0
    syn = np.full((2, 3), np.inf)
    syn[0, 0] = 0.5
    real = ViewDepth(np.array([[np.nan, 0.2, 0.4], [np.nan] * 3], np.float32), np.full((2, 3), 0.001, np.float32), "x")
    out = depth_layer(real, syn)
    left, right = out[:, :3].astype(int), out[:, 3:].astype(int)
    assert left[0, 1, 0] > left[0, 2, 0] > 0 and left[0, 0].max() == 0 and left[1].max() == 0   # 0.2 m brighter
    assert right[0, 0, 2] > 0 and right[0, 1:].max() == 0 and right[0, 0, 2] < left[0, 1, 0]    # 0.5 m the farthest


def _started(session):
    """Start a session's loop; returns the list its callbacks fill, in order: ("frame", ViewerFrame),
    ("bounces", ViewerBounces) and ("message", dict)."""
    events: list = []
    lock = threading.Lock()

    def add(kind):
        def callback(item):
            with lock:
                events.append((kind, item))
        return callback

    session.start(add("frame"), add("error"), add("bounces"), add("message"))
    return events


def _wait(predicate, timeout: float, what: str) -> None:
    end = time.time() + timeout
    while time.time() < end:
        if predicate():
            return
        time.sleep(0.02)
    raise AssertionError(f"{what}: not within {timeout} s")


def test_05_bounce_layers_on_demand(variant, tmp_path):
    """Asked for, the bounce loop runs between two live frames (none comes while it runs) on the scene as edited
    and gives one real and one synthetic layer per bounce with finite positive gains, the bounce-1 layers not
    black (the two objects exchange light); a second request meanwhile is dropped; the loop goes on afterwards,
    and a paused loop stays paused."""
    import cv2

    from lftransfer.app.viewer.command import open_session

    session = open_session(_tiny_scene(), rig_model="oracle", truth_seed=None, out=tmp_path)
    events = _started(session)
    try:
        _wait(lambda: sum(k == "frame" for k, _ in events) >= 2, 60, "two live frames")
        session.submit({"type": "object", "side": "synthetic", "index": 0, "translate": [0.01, 0.0, -0.08]})
        assert session.submit({"type": "bounces", "bounces": 2}) == {"type": "ack", "edit": "bounces"}
        assert session.submit({"type": "bounces"})["queued"] is False
        _wait(lambda: any(k == "bounces" and b.state != "running" for k, b in events), 60, "the bounce layers")
        kinds = [(k, getattr(x, "state", None)) for k, x in events]
        first, done = kinds.index(("bounces", "running")), kinds.index(("bounces", "done"))
        assert all(k == "bounces" for k, _ in kinds[first:done]), "a live frame came while the bounce loop ran"
        result = events[done][1]
        assert session.scene.synthetic[0].translate == [0.01, 0.0, -0.08]      # the edit before it was applied
        assert result.bounces == 2 and result.error is None and result.elapsed_s > 0
        for side in ("real", "synthetic"):
            assert [x["index"] for x in result.layers if x["side"] == side] == [0, 1, 2]
        gains = np.array([x["gain"] for x in result.layers])
        assert np.all(np.isfinite(gains)) and np.all(gains > 0) and np.all(gains[[0, 3]] == 1.0)

        def pixels(data: bytes) -> np.ndarray:
            return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)

        for x in result.layers:
            if x["index"] == 1:
                assert pixels(x["image"]).max() > 40, x["title"]            # not black
        assert pixels(result.composite).max() > 40
        assert set(result.message()) >= {"type", "state", "layers", "composite", "elapsed_s"}
        count = len(events)
        _wait(lambda: sum(k == "frame" for k, _ in events[count:]) >= 2, 30, "live frames after the bounce loop")

        session.submit({"type": "pause"})
        _wait(lambda: session.paused, 30, "the pause")
        session.submit({"type": "bounces", "bounces": 1})
        _wait(lambda: sum(k == "bounces" and b.state == "done" for k, b in events) == 2, 60, "the second layers")
        count = sum(k == "frame" for k, _ in events)
        time.sleep(0.3)
        assert session.paused and sum(k == "frame" for k, _ in events) == count      # paused, as it was
        session.submit({"type": "resume"})
        _wait(lambda: sum(k == "frame" for k, _ in events) >= count + 2, 30, "live frames after resuming")
    finally:
        session.close()


def test_06_bounce_layers_failure_is_shown(variant, tmp_path, monkeypatch):
    """A bounce loop that fails (here: the rig) ends in a "failed" message with the reason; the live loop goes on
    and a later request works again."""
    from lftransfer.app.viewer import session as session_module
    from lftransfer.app.viewer.command import open_session
    from lftransfer.rig.base import RigError

    def broken(*_args, **_kwargs):
        raise RigError("the projector does not answer")

    session = open_session(_tiny_scene(), rig_model="oracle", truth_seed=None, out=tmp_path)
    monkeypatch.setattr(session_module, "transfer_through", broken)
    events = _started(session)
    try:
        session.submit({"type": "bounces"})
        _wait(lambda: any(k == "bounces" and b.state == "failed" for k, b in events), 60, "the failure")
        failed = next(b for k, b in events if k == "bounces" and b.state == "failed")
        assert failed.error == "bounce layers failed: RigError: the projector does not answer"
        assert failed.message()["error"] == failed.error and not failed.layers
        count = sum(k == "frame" for k, _ in events)
        _wait(lambda: sum(k == "frame" for k, _ in events) >= count + 2, 30, "live frames after the failure")
        monkeypatch.undo()
        session.submit({"type": "bounces"})
        _wait(lambda: any(k == "bounces" and b.state == "done" for k, b in events), 60, "the bounce layers")
    finally:
        session.close()


class _LostPage:
    """A page's websocket whose peer has gone: every send fails (and, as in starlette, marks the socket closed),
    and the next receive raises the RuntimeError starlette raises on a closed socket."""

    def __init__(self, closes: bool = True) -> None:
        from fastapi.websockets import WebSocketState

        self.application_state = WebSocketState.CONNECTED
        self._closed, self._closes = WebSocketState.DISCONNECTED, closes

    async def accept(self) -> None:
        pass

    async def send_text(self, text: str) -> None:
        if self._closes:
            self.application_state = self._closed
        raise OSError("connection reset by peer")

    async def receive_text(self) -> str:
        raise RuntimeError('WebSocket is not connected. Need to call "accept" first.')


def test_07_a_lost_page_ends_its_socket_quietly(session):
    """A page that goes away while a frame is sent to it ends its own socket without an error (the loop and the
    other pages go on); a RuntimeError on a socket that is still open is a real fault and is raised."""
    import asyncio

    from lftransfer.app.viewer.server import make_app

    app = make_app(session)
    handler = next(r.endpoint for r in app.routes if getattr(r, "path", None) == "/ws")
    lost = _LostPage()
    asyncio.run(handler(lost))
    assert lost not in app.state.clients.layers
    with pytest.raises(RuntimeError, match="not connected"):
        asyncio.run(handler(_LostPage(closes=False)))


def test_08_decoupled_session_compare_and_record(variant, tmp_path):
    """The page's session runs the decoupled loop: frames say the capture rate and age, an edit's latency is
    counted; "compare" renders the ground truth of the frame shown while frames go on, with the PSNR, the
    reference's own noise and a difference image that is not black (negative control: the composite is not the
    ground truth); "record" writes the frames shown to an MP4 with as many frames."""
    from lftransfer.app.viewer.command import open_session

    session = open_session(_tiny_scene(), rig_model="oracle", truth_seed=None, out=tmp_path)
    assert session.live.loop == "decoupled"
    events = _started(session)
    frames = lambda: [x for k, x in events if k == "frame"]          # noqa: E731
    messages = lambda: [x for k, x in events if k == "message"]      # noqa: E731
    try:
        _wait(lambda: len(frames()) >= 3, 60, "three frames")
        last = frames()[-1]
        assert last.loop == "decoupled" and last.capture_hz > 0 and last.capture_age_s > 0
        assert set(last.capture_ms) == {"encode", "capture", "decode", "capture_view"}
        session.submit({"type": "object", "side": "synthetic", "index": 0, "translate": [0.01, 0.0, -0.08]})
        _wait(lambda: (frames()[-1].latency_ms["light"] or {}).get("count", 0) >= 1, 60, "the edit's light")
        lat = frames()[-1].latency_ms
        assert 0 < lat["view"]["median"] <= lat["light"]["median"]

        assert session.submit({"type": "compare"}) == {"type": "ack", "edit": "compare"}
        _wait(lambda: any(m.get("type") == "compare" and "psnr_db" in m for m in messages()), 120, "the comparison")
        done = next(m for m in messages() if m.get("type") == "compare" and "psnr_db" in m)
        assert done["error"] is None and 10 < done["psnr_objects_db"] < 80 and done["noise_psnr_db"] > 10
        assert _pixels(done["difference"]).max() > 0 and _pixels(done["ground_truth"]).max() > 40
        assert any(m.get("state") == "running" for m in messages() if m.get("type") == "compare")

        session.submit({"type": "record", "on": True})
        _wait(lambda: any(m.get("type") == "recording" for m in messages()), 30, "the recording's start")
        count = len(frames())
        _wait(lambda: len(frames()) >= count + 6, 60, "frames while recording")
        session.submit({"type": "record", "on": False})
        _wait(lambda: any(m.get("type") == "recorded" for m in messages()), 60, "the recording")
        rec = next(m for m in messages() if m.get("type") == "recorded")
        assert rec["error"] is None and rec["frames"] >= 6 and rec["dropped"] == 0
        import imageio.v2 as iio2

        reader = iio2.get_reader(rec["path"], format="FFMPEG")
        assert sum(1 for _ in reader) == rec["frames"]
        reader.close()
        with pytest.raises(Exception, match="on: expected true or false"):
            session.submit({"type": "record", "on": "yes"})

        session.submit({"type": "pause"})                       # a paused page rests the rig as well
        _wait(lambda: session.paused, 30, "the pause")
        time.sleep(1.0)                                          # the capture in progress finishes
        count = session.live._worker.count
        time.sleep(1.5)
        assert session.live._worker.count == count
        session.submit({"type": "resume"})
        _wait(lambda: session.live._worker.count > count, 30, "captures after resuming")

        # the simulator renders in its own process; the frames say the cores each side keeps busy
        busy = frames()[-1].cores_busy
        assert busy["cores"] >= 1 and busy["loop"] > 0 and busy["simulator"] is not None and busy["turns"] is None
        # a simulator that dies ends the loop with one line naming it; the page is told
        pid = session.live.rig.pid
        os.kill(pid, signal.SIGKILL)
        _wait(lambda: session.failed is not None, 60, "the loop to stop")
        assert session.failed.startswith(f"the live loop stopped: the capture worker stopped: RigError: the "
                                         f"simulator process (pid {pid}) died")
        assert "\n" not in session.failed and any(k == "error" and x == session.failed for k, x in events)
        count = len(frames())
        time.sleep(1.0)
        assert len(frames()) == count                           # no frame after it
    finally:
        session.close()


def test_09_the_page_resolves_its_settings_as_the_command_line_does(session):
    """The session keeps what the command asked for and resolves it again for the scene as edited: the same
    settings resolve_settings gives a live loop, the renderer final, and a glossy object edited below the fast
    path's verified roughness taking the exact path; a bounce-layer request resolves its bounces the same way."""
    from lftransfer.settings import resolve_settings

    views = session.live.settings.bounce_views
    assert session.resolved() == resolve_settings(session.scene, session.overrides, live=True,
                                                  bounce_views=views).transfer
    assert session.resolved().renderer == "fast"
    cube = session.scene.synthetic[0].model_dump(mode="json")
    saved = session.scene
    try:
        session.scene = with_overrides(saved, synthetic=[{**cube, "material": {"type": "glossy", "roughness": 0.01}}])
        assert session.resolved().renderer == "exact"
    finally:
        session.scene = saved
    assert session.resolved(bounces=3, bounce_views=True).bounces == 3


def test_10_the_server_stops_when_the_loop_stopped_on_a_failed_rig(monkeypatch):
    """``serve`` returns once the session's loop has ended on its own (``session.failed``: a dead simulator), so
    that ``lft live`` can end on that one line; before that it keeps serving."""
    from lftransfer.app.viewer import server

    class Session:                     # the little of a LiveSession that serving needs
        failed = None
        started = stopped = False

        def start(self, *callbacks):
            self.started = True

        def stop(self):
            self.stopped = True

    session = Session()
    monkeypatch.setattr(server, "make_app", lambda s: server.FastAPI(lifespan=_lifespan(s)))
    thread = threading.Thread(target=server.serve, args=(session,), kwargs={"port": _free_port()}, daemon=True)
    thread.start()
    time.sleep(1.5)
    assert thread.is_alive() and session.started                 # serving while the loop runs
    session.failed = "the live loop stopped: the simulator process (pid 1) died (exit code -9) during capture_lf"
    thread.join(10)
    assert not thread.is_alive() and session.stopped


def _lifespan(session):
    import contextlib

    @contextlib.asynccontextmanager
    async def lifespan(_app):
        session.start()
        try:
            yield
        finally:
            session.stop()
    return lifespan


def test_11_a_session_through_two_interfaces(variant, tmp_path):
    """The page on the corner's two arrays: the live loop exchanges through both (the decoupled loop's simulator
    in this process, and said so); the "captured" layer and the panel show a row for each interface's LF camera and
    projector; a real object moved by the page moves in the world both arrays see; the bounce layers run through
    both."""
    from lftransfer.app.viewer.command import open_session
    from tests.transfer.test_interfaces import _corner

    warnings = []
    session = open_session(_corner(lamp=True), rig_model="oracle", truth_seed=None, out=tmp_path,
                           warn=warnings.append)
    try:
        live = session.live
        assert len(live.rigs) == 2 and live.loop == "decoupled"
        assert any("simulator: in this process" in w for w in warnings)
        frames = [live.step(0.0) for _ in range(2)]
        assert [len(f.interfaces) for f in frames] == [2, 2]
        session.scale = 1.0
        captured = session._layer(frames[-1], "captured")
        w, h = session.scene.rig.projector
        assert captured.shape[:2] == (2 * h, 2 * w)           # per interface: its LF camera, its projector
        for row in (captured[:h], captured[h:]):
            assert row[h // 4:, :w].max() > 0                 # below the labels: each LF camera sees the block
        panel = session._layer(frames[-1], "panel")
        view_h, view_w = frames[-1].composite.shape[:2]
        assert round(panel.shape[0] / (panel.shape[1] / 3 * view_h / view_w)) == 3      # two interfaces, the views
        moved = [o.model_dump() for o in session.sim_rig.real_objects]
        moved[0]["translate"] = [0.005, 0.0, 0.06]
        with live.holding_rigs() as rigs:
            session.sim_rig.place_real(moved)
            assert all(r.real_objects[0].translate == [0.005, 0.0, 0.06] for r in rigs)
        layers = session.bounce_layers(1)
        assert layers.state == "done", layers.error
        assert [x["index"] for x in layers.layers if x["side"] == "synthetic"] == [0, 1]
    finally:
        session.close()
