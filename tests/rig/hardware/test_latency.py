"""Latency: measured through a real display -> capture path (a camera that films the Xvfb window)."""

from __future__ import annotations

import collections
import time

import cv2
import numpy as np
import pytest

from lftransfer.rig.base import RigError
from lftransfer.rig.hardware import calibrate_latency, load_rig_file, measure_latency
from lftransfer.rig.hardware.camera import OpenCVCamera
from lftransfer.rig.hardware.config import CameraConfig, ProjectorConfig
from lftransfer.rig.hardware.latency import settle_time
from lftransfer.rig.hardware.projector import ProjectorWindow

from .conftest import SCREEN

CAM = (32, 24)
SLACK_S = 1.5        # a bound on a hang, not a speed benchmark


class ScreenCapture:
    """A cv2.VideoCapture stand-in that films the projector window: each read() grabs the window (XGetImage),
    shrinks it to the camera's size and hands it out ``lag`` frames later, at about ``fps`` frames a second."""

    def __init__(self, window, lag=2, fps=60.0, frozen=False):
        self.window = window
        self.pipeline = collections.deque()
        self.lag = lag
        self.period = 1.0 / fps
        self.frozen = frozen
        self.last = time.monotonic()

    def isOpened(self):
        return True

    def read(self):
        wait = self.last + self.period - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        self.last = time.monotonic()
        shot = np.zeros((SCREEN[1], SCREEN[0], 3), np.uint8) if self.frozen else self.window.screenshot()
        self.pipeline.append(cv2.resize(shot, CAM, interpolation=cv2.INTER_AREA)[..., ::-1].copy())
        while len(self.pipeline) > self.lag + 1:
            self.pipeline.popleft()
        return True, self.pipeline[0]

    def set(self, prop, value):
        return False

    def get(self, prop):
        return 0.0

    def release(self):
        pass


def _camera(window, **kw):
    config = CameraConfig(source=0, width=CAM[0], height=CAM[1], timeout_s=2.0)
    return OpenCVCamera(config, "LF camera", capture_factory=lambda *a: ScreenCapture(window, **kw)).open()


def test_01_latency_of_a_camera_watching_the_window(display):
    with ProjectorWindow(ProjectorConfig(width=SCREEN[0], height=SCREEN[1])) as window, _camera(window) as cam:
        seen = []
        start = time.monotonic()
        result = measure_latency(window, cam, tries=6, timeout_s=2.0, prime_s=0.2,
                                 progress=lambda i, n, d: seen.append((i, n, d)))
        elapsed = time.monotonic() - start
    assert len(result.samples) == 6 and [s[0] for s in seen] == list(range(6))
    assert 0.0 < result.median_s <= result.max_s < 2.0
    assert result.max_s == max(result.samples) and result.settle_s is None
    assert result.black_level < 5 and result.marker_level > 250        # black and full white, 8-bit codes
    assert elapsed < 6 * 2 * 2.0 + 1.0
    # two frames of camera lag at 60 fps: at least one frame period
    assert result.median_s >= 1 / 60 - 1e-3


def test_02_calibrate_writes_settle_time(tmp_path, display):
    path = tmp_path / "rig.toml"
    path.write_text(f"""# rig
[lf_camera]
source = 0
width = {CAM[0]}
height = {CAM[1]}

[view_camera]
source = 1
width = 8
height = 8

[projector]
width = {SCREEN[0]}
height = {SCREEN[1]}
settle_s = 5.0   # measured
""")
    prompts = []
    with ProjectorWindow(load_rig_file(path).projector) as window, _camera(window) as cam:
        result = calibrate_latency(path, tries=3, timeout_s=2.0, operator=prompts.append, projector=window,
                                   camera=cam)
    assert len(prompts) == 1 and "diffuser" in prompts[0]
    assert result.settle_s == settle_time(result) and result.settle_s >= result.max_s + 0.02
    assert load_rig_file(path).projector.settle_s == result.settle_s
    assert f"settle_s = {result.settle_s!r}   # measured\n" in path.read_text()


def test_03_marker_never_seen(display):
    with ProjectorWindow(ProjectorConfig(width=SCREEN[0], height=SCREEN[1])) as window, \
            _camera(window, frozen=True) as cam:
        start = time.monotonic()
        with pytest.raises(RigError, match=r"LF camera \(0\): the camera never saw the projector's marker within "
                                            r"0\.5 s .*is the camera looking through the array / is the projector "
                                            r"on\?"):
            measure_latency(window, cam, tries=3, timeout_s=0.5, prime_s=0.1)
        assert time.monotonic() - start < 0.1 + 0.5 + SLACK_S


def test_04_settle_time_rule():
    from lftransfer.rig.hardware.latency import LatencyResult

    r = LatencyResult(median_s=0.05, max_s=0.2, samples=(0.05, 0.2), black_level=0.0, marker_level=1.0)
    assert settle_time(r) == 0.25                     # max + 25 %
    r = LatencyResult(median_s=0.01, max_s=0.0401, samples=(0.0401,), black_level=0.0, marker_level=1.0)
    assert settle_time(r) == 0.061                    # max + 20 ms, rounded up to a whole millisecond
