"""Cameras: recordings read exactly through OpenCV, averaging, bounded waits on a camera that stops, GenICam."""

from __future__ import annotations

import sys
import threading
import time
import types

import cv2
import numpy as np
import pytest

from lftransfer.rig.base import RigError
from lftransfer.rig.hardware.camera import GenICamCamera, OpenCVCamera
from lftransfer.rig.hardware.cameras import open_camera
from lftransfer.rig.hardware.config import CameraConfig

SLACK_S = 1.5        # a bound on a hang, not a speed benchmark


def _sequence(folder, frames, pattern="%04d.png"):
    folder.mkdir(parents=True, exist_ok=True)
    for i, f in enumerate(frames):
        bgr = f[..., ::-1] if f.ndim == 3 else f
        assert cv2.imwrite(str(folder / (pattern % i)), np.ascontiguousarray(bgr))
    return str(folder / pattern)


def _config(source, width, height, **kw):
    return CameraConfig(source=source, width=width, height=height, **kw)


def test_01_image_sequence_is_read_exactly_and_averaged(tmp_path):
    rng = np.random.default_rng(1)
    frames = [rng.integers(0, 4096, (24, 32, 3), dtype=np.uint16) for _ in range(6)]
    cam = open_camera(_config(_sequence(tmp_path / "seq", frames), 32, 24, bits=12), "LF camera")
    with cam:
        first, _ = cam.read_frame()
        assert first.dtype == np.float32 and first.shape == (24, 32, 3)
        assert np.array_equal(first, frames[0].astype(np.float32))           # RGB order, exact codes
        mean = cam.grab(frames=3, drop=1)                                    # drops frame 1, averages 2..4
        expected = np.mean([f.astype(np.float64) for f in frames[2:5]], axis=0)
        assert np.allclose(mean, expected, atol=1e-3)
        with pytest.raises(RigError, match=r"LF camera \(.*%04d\.png\): the recording ended after 6 frames "
                                            r"during capture_lf after projecting"):
            cam.grab(frames=2, step="capture_lf after projecting")


def test_02_lossless_video_file_and_grey_frames(tmp_path):
    rng = np.random.default_rng(2)
    frames = [rng.integers(0, 256, (48, 64, 3), dtype=np.uint8) for _ in range(4)]
    path = tmp_path / "v.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), 30, (64, 48))
    assert writer.isOpened()
    for f in frames:
        writer.write(np.ascontiguousarray(f[..., ::-1]))
    writer.release()
    with open_camera(_config(str(path), 64, 48), "view camera") as cam:
        for f in frames[:2]:
            assert np.array_equal(cam.read_frame()[0], f.astype(np.float32))
        assert np.allclose(cam.grab(2), (frames[2].astype(np.float64) + frames[3]) / 2)

    grey = [rng.integers(0, 256, (10, 12), dtype=np.uint8) for _ in range(2)]
    with open_camera(_config(_sequence(tmp_path / "grey", grey), 12, 10, bits=10)) as cam:
        codes, _ = cam.read_frame()
        assert codes.shape == (10, 12, 3)
        assert np.allclose(codes, np.repeat(grey[0][..., None], 3, 2) * (1023 / 255), atol=1e-3)


def test_03_wrong_size_and_missing_source(tmp_path):
    frames = [np.zeros((24, 32, 3), np.uint8)]
    with open_camera(_config(_sequence(tmp_path / "s", frames), 40, 30), "LF camera") as cam:
        with pytest.raises(RigError, match=r"LF camera \(.*\): the camera delivers 32x24 frames, the rig file says "
                                            r"40x30"):
            cam.read_frame()
    with pytest.raises(RigError, match=r"view camera \(.*missing\.avi\): cannot open the camera: no such video"):
        open_camera(_config(str(tmp_path / "missing.avi"), 8, 8), "view camera")
    with pytest.raises(RigError, match=r"LF camera \(.*nothing_%03d\.png\): cannot open the camera"):
        open_camera(_config(str(tmp_path / "nothing_%03d.png"), 8, 8), "LF camera")


class FakeCapture:
    """A cv2.VideoCapture stand-in: frames from a callable; can block forever or fail."""

    def __init__(self, frame, block_after=None, fail=False, exposure=None):
        self.frame = frame
        self.block_after = block_after
        self.fail = fail
        self.reads = 0
        self.released = threading.Event()
        self.props = {cv2.CAP_PROP_EXPOSURE: exposure} if exposure is not None else {}

    def isOpened(self):
        return True

    def read(self):
        self.reads += 1
        if self.block_after is not None and self.reads > self.block_after:
            self.released.wait()                   # a driver that never returns
            return False, None
        if self.fail:
            return False, None
        return True, self.frame()

    def set(self, prop, value):
        if prop in self.props:
            self.props[prop] = float(value)
            return True
        return False

    def get(self, prop):
        return self.props.get(prop, 0.0)

    def release(self):
        self.released.set()


def _fake_camera(cap, timeout_s=0.5, source=2, role="LF camera", **kw):
    cam = OpenCVCamera(_config(source, 8, 6, timeout_s=timeout_s, **kw), role,
                       capture_factory=lambda *a: cap)
    return cam.open()


def test_04_camera_that_blocks_raises_within_the_timeout():
    frame = np.full((6, 8, 3), 7, np.uint8)
    cap = FakeCapture(lambda: frame, block_after=2)
    cam = _fake_camera(cap, timeout_s=0.5, source="/dev/video7")
    try:
        cam.grab(2)
        start = time.monotonic()
        with pytest.raises(RigError, match=r"LF camera \(/dev/video7\): no answer within 0\.5 s while reading "
                                            r"frame 3 \(capture_lf after projecting\)"):
            cam.grab(1, step="capture_lf after projecting")
        elapsed = time.monotonic() - start
        assert elapsed < 0.5 + SLACK_S, elapsed
        # the worker is still blocked: the next call fails at once instead of queueing behind it
        start = time.monotonic()
        with pytest.raises(RigError, match=r"LF camera \(/dev/video7\): the camera stopped responding earlier"):
            cam.grab(1, step="capture_view after projecting")
        assert time.monotonic() - start < SLACK_S
    finally:
        cap.released.set()
        cam.close()
        cam.close()                                      # idempotent


def test_05_live_camera_without_frames_raises_within_the_timeout():
    cap = FakeCapture(lambda: None, fail=True)
    cam = _fake_camera(cap, timeout_s=0.4, source=3, role="view camera")
    start = time.monotonic()
    with pytest.raises(RigError, match=r"view camera \(3\): no frame within 0\.4 s during capture_view after "
                                        r"projecting"):
        cam.grab(1, step="capture_view after projecting")
    assert 0.4 <= time.monotonic() - start < 0.4 + SLACK_S
    cam.close()


def test_06_exposure_bracketing(tmp_path):
    frame = np.zeros((6, 8, 3), np.uint8)
    cap = FakeCapture(lambda: frame, exposure=100.0)
    cam = _fake_camera(cap, exposure=100.0)
    cam.set_exposure_scale(4.0)
    assert cap.props[cv2.CAP_PROP_EXPOSURE] == 400.0 and cam.exposure_scale == 4.0
    cam.set_exposure_scale(1.0)
    assert cap.props[cv2.CAP_PROP_EXPOSURE] == 100.0
    cam.close()

    seq = _sequence(tmp_path / "s", [np.zeros((6, 8, 3), np.uint8)])
    with open_camera(_config(seq, 8, 6), "LF camera") as cam:
        cam.set_exposure_scale(1.0)                      # nothing to change
        with pytest.raises(RigError, match=r"LF camera \(.*\): exposure bracketing \(exposure_scale 2\) is not "
                                            r"supported by this camera"):
            cam.set_exposure_scale(2.0, step="capture_lf after projecting")


def test_07_genicam_without_harvesters_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "harvesters", None)
    monkeypatch.setitem(sys.modules, "harvesters.core", None)
    config = _config("genicam:1234", 8, 6, cti="/nonexistent/producer.cti")
    start = time.monotonic()
    with pytest.raises(RigError, match=r"pip install lftransfer\[genicam\]"):
        open_camera(config, "LF camera")
    assert time.monotonic() - start < SLACK_S


def _fake_harvesters(monkeypatch, payloads):
    """A minimal harvesters.core stand-in delivering ``payloads`` ((data, format) pairs)."""

    class Node:
        def __init__(self, value):
            self.value = value

    class Buffer:
        def __init__(self, data, fmt):
            comp = types.SimpleNamespace(data=data.ravel(), height=data.shape[0], width=data.shape[1],
                                         data_format=fmt)
            self.payload = types.SimpleNamespace(components=[comp])

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

    class Acquirer:
        def __init__(self):
            self.remote_device = types.SimpleNamespace(node_map=types.SimpleNamespace(
                ExposureTime=Node(1000.0), ExposureAuto=Node("Continuous"), Gain=Node(0.0)))
            self.started = self.destroyed = False

        def start(self):
            self.started = True

        def fetch(self, timeout):
            return Buffer(*payloads.pop(0))

        def stop(self):
            self.started = False

        def destroy(self):
            self.destroyed = True

    class Harvester:
        last = None

        def __init__(self):
            self.files = []
            self.device_info_list = [types.SimpleNamespace(serial_number="SN42")]
            Harvester.last = self

        def add_file(self, path):
            self.files.append(path)

        def update(self):
            pass

        def create(self, key):
            assert key == {"serial_number": "SN42"}
            self.ia = Acquirer()
            return self.ia

        def reset(self):
            pass

    core = types.ModuleType("harvesters.core")
    core.Harvester = Harvester
    monkeypatch.setitem(sys.modules, "harvesters", types.ModuleType("harvesters"))
    monkeypatch.setitem(sys.modules, "harvesters.core", core)
    return Harvester


def test_08_genicam_camera_through_a_fake_harvester(tmp_path, monkeypatch):
    cti = tmp_path / "producer.cti"
    cti.write_bytes(b"")
    rng = np.random.default_rng(3)
    mono = rng.integers(0, 4096, (6, 8), dtype=np.uint16)
    bayer = rng.integers(0, 256, (6, 8), dtype=np.uint8)
    H = _fake_harvesters(monkeypatch, [(mono, "Mono12"), (bayer, "BayerRG8")])
    config = _config("genicam:SN42", 8, 6, cti=str(cti), bits=12, exposure=500.0, gain=2.0)
    cam = open_camera(config, "LF camera")
    assert isinstance(cam, GenICamCamera)
    nodes = H.last.ia.remote_device.node_map
    assert nodes.ExposureTime.value == 500.0 and nodes.ExposureAuto.value == "Off" and nodes.Gain.value == 2.0
    codes, _ = cam.read_frame()
    assert np.array_equal(codes, np.repeat(mono[..., None], 3, 2).astype(np.float32))
    codes, _ = cam.read_frame()
    expected = cv2.cvtColor(bayer, cv2.COLOR_BayerRGGB2RGB).astype(np.float32) * (4095 / 255)
    assert np.allclose(codes, expected, atol=1e-2)
    cam.set_exposure_scale(0.5)
    assert nodes.ExposureTime.value == 250.0
    cam.close()
    assert H.last.ia.destroyed

    with pytest.raises(RigError, match=r"LF camera \(genicam:SN7\): cannot open the camera: no camera with serial "
                                        r"number SN7 \(found: SN42\)"):
        open_camera(_config("genicam:SN7", 8, 6, cti=str(cti)), "LF camera")
