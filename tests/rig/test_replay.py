"""Recording a rig and replaying it: every answer comes back bit for bit; what the recording lacks is named."""

from __future__ import annotations

import hashlib
import json
import logging
import math
from functools import partial

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lftransfer.rig import replay as replay_module
from lftransfer.rig.base import Rig, RigError
from lftransfer.rig.replay import RecordingRig, ReplayError, ReplayRig
from lftransfer.rig.requests import (Board, Collimator, FocalPlaneDiffuser, LFCapture, LFFrame, MirrorBall, RealScene,
                                     RigInfo, ViewCapture, ViewFrame, WhiteField, describe, image_digest, request_key,
                                     setup_from_json)

INFO = RigInfo(lf_camera=(40, 32), lf_camera_bits=12, projector=(20, 16), projector_bits=8, view=(24, 18),
               kind="fake")


class FakeRig:
    """Deterministic but noisy-looking answers that depend on the set-up, the projected image, the request and
    a capture counter (so repeated captures differ)."""

    def __init__(self, info: RigInfo = INFO, view_shape=None, lf_dtype=np.uint16):
        self._info = info
        self._setup = RealScene()
        self._projected = None
        self.counter = 0
        self.closed = False
        self.view_shape = view_shape or (info.view[1], info.view[0], 3)
        self.lf_dtype = lf_dtype

    @property
    def info(self) -> RigInfo:
        return self._info

    def setup(self, request) -> None:
        self._setup = request

    def project(self, image) -> None:
        self._projected = image_digest(self._info.check_projector_image(image))

    def _rng(self, request) -> np.random.Generator:
        self.counter += 1
        seed = hashlib.sha256(f"{request_key(self._setup, self._projected, request)}|{self.counter}".encode())
        return np.random.default_rng(int.from_bytes(seed.digest()[:8], "little"))

    def capture_lf(self, request=LFCapture()) -> LFFrame:
        rng = self._rng(request)
        w, h = self._info.lf_camera
        full = 2 ** self._info.lf_camera_bits - 1
        signal = rng.uniform(0, 0.5 * full, (h, w, 3)) * request.exposure_scale
        codes = np.clip(rng.poisson(signal) + rng.normal(0, 2, signal.shape), 0, full)
        return LFFrame(codes=codes.astype(self.lf_dtype), bits=self._info.lf_camera_bits,
                       exposure_scale=request.exposure_scale)

    def capture_view(self, request=ViewCapture()) -> ViewFrame:
        rng = self._rng(request)
        radiance = (rng.gamma(2.0, 0.3, self.view_shape) * rng.uniform(0.5, 2)).astype(np.float32)
        if radiance.ndim == 3 and radiance.shape[2] == 3:  # bit patterns a lossy or half-float store would lose
            radiance[0, :6, 0] = [np.nan, -0.0, np.inf, 1e-42, 3.4e38, np.float32(1) + np.float32(2 ** -23)]
            radiance[0, 0, 1] = np.uint32(0x7FC12345).view(np.float32)      # NaN with a payload
        return ViewFrame(radiance=radiance)

    def close(self) -> None:
        self.closed = True


def _pattern(value: int, info: RigInfo = INFO) -> np.ndarray:
    img = info.black()
    img[::2, ::3] = value
    img[..., 1] = np.arange(img.shape[1], dtype=img.dtype)[None, :] * (value % 7)
    return img


BOARD = Board(centre=(0.01, -0.02, 0.08), normal=(0.1, 0.0, 1.0), size=(0.2, 0.15), chart=(7, 5, 0.02))


def _session(rig):
    """A run's worth of requests; returns the answers in order."""
    out = []
    out.append(rig.capture_lf())                                   # start: real scene, nothing projected
    rig.project(_pattern(0))
    out += [rig.capture_lf() for _ in range(3)]                    # the same request three times
    out += [rig.capture_lf(LFCapture(exposure_scale=s)) for s in (0.25, 1.0, 4.0)]    # bracketing
    out += [rig.capture_view(), rig.capture_view(ViewCapture(frames=4, quality=64)), rig.capture_view()]
    rig.setup(Collimator(direction=(0.1, -0.05, 1.0)))
    out.append(rig.capture_lf(LFCapture(frames=8)))
    rig.setup(WhiteField())
    out.append(rig.capture_lf())
    rig.setup(FocalPlaneDiffuser(transmission=0.4))
    for v in (50, 200, 50):                                        # an image projected again later
        rig.project(_pattern(v))
        out.append(rig.capture_lf())
    rig.setup(BOARD)
    rig.project(_pattern(255))
    out += [rig.capture_lf(), rig.capture_view(), rig.capture_lf(LFCapture(exposure_scale=0.5)), rig.capture_lf()]
    rig.setup(RealScene())
    rig.project(_pattern(0))
    out += [rig.capture_lf(), rig.capture_view()]
    return out


def _same(a, b) -> bool:
    """Bit-identical frames (NaNs included)."""
    if type(a) is not type(b):
        return False
    x, y = (a.codes, b.codes) if isinstance(a, LFFrame) else (a.radiance, b.radiance)
    same = x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes()
    if isinstance(a, LFFrame):
        return same and a.bits == b.bits and a.exposure_scale == b.exposure_scale and np.array_equal(x, y)
    return same and np.array_equal(x, y, equal_nan=True)


def _png(path):
    """(header, image) of a PNG: (width, height, bit depth, colour type) from its IHDR chunk, and the pixels as
    OpenCV reads them (BGR) turned back to RGB (Pillow, hence imageio, reads 16-bit RGB as 8-bit)."""
    import cv2

    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR"
    header = (int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big"), data[24], data[25])
    return header, cv2.imread(str(path), cv2.IMREAD_UNCHANGED)[..., ::-1]


def _record(folder, fake=None, **kwargs):
    fake = fake or FakeRig()
    rig = RecordingRig(fake, folder, meta={"scene": folder / "scene.toml", "truth_seed": 7}, **kwargs)
    answers = _session(rig)
    rig.close()
    return fake, answers


@pytest.mark.parametrize("workers, view_format", [(None, "pfm"), (0, "pfm"), (2, "exr"), (0, "exr")])
def test_01_replay_answers_bit_for_bit(tmp_path, workers, view_format):
    fake = FakeRig()
    rig = RecordingRig(fake, tmp_path / "rec", workers=workers, view_format=view_format)
    assert isinstance(rig, Rig)
    originals = []

    class Spy:                           # what the fake returned, to compare with what the recorder passed on
        info = fake.info

        def __getattr__(self, name):
            return getattr(rig, name)

        def capture_lf(self, request=LFCapture()):
            frame = rig.capture_lf(request)
            originals.append(LFFrame(frame.codes.copy(), frame.bits, frame.exposure_scale))
            frame.codes[:] = 0           # the caller may change what it got: the recording holds a copy
            return frame

        def capture_view(self, request=ViewCapture()):
            frame = rig.capture_view(request)
            originals.append(ViewFrame(frame.radiance.copy()))
            return frame

    _session(Spy())
    rig.close()
    assert fake.closed and len(originals) == 21
    assert len(list((tmp_path / "rec" / "view").glob(f"*.{view_format}"))) == 5

    replay = ReplayRig(tmp_path / "rec", strict=True)
    assert isinstance(replay, Rig) and replay.remaining() == 21
    replayed = _session(replay)
    assert all(_same(a, b) for a, b in zip(originals, replayed)), \
        [i for i, (a, b) in enumerate(zip(originals, replayed)) if not _same(a, b)]
    assert replay.remaining() == 0
    # the three identical requests got three different answers, in recorded order
    assert not np.array_equal(replayed[1].codes, replayed[2].codes)
    assert [f.exposure_scale for f in replayed[4:7]] == [0.25, 1.0, 4.0]


def test_02_repeated_requests_in_order_and_no_more(tmp_path):
    fake = FakeRig()
    rig = RecordingRig(fake, tmp_path / "rec")
    rig.setup(BOARD)
    recorded = [rig.capture_lf().codes.copy() for _ in range(3)]
    rig.close()
    replay = ReplayRig(tmp_path / "rec")
    replay.setup(Board(centre=(0.01, -0.02, 0.08), normal=(0.1, 0.0, 1.0), size=(0.2, 0.15), chart=(7, 5, 0.02)))
    for codes in recorded:
        assert np.array_equal(replay.capture_lf().codes, codes)
    with pytest.raises(ReplayError, match=r"more often than recorded.*holds 3 answer"):
        replay.capture_lf()


def test_03_missing_request_is_named(tmp_path):
    _record(tmp_path / "rec")
    replay = ReplayRig(tmp_path / "rec")
    replay.setup(BOARD)
    other = _pattern(17)
    replay.project(other)
    with pytest.raises(ReplayError) as err:
        replay.capture_lf(LFCapture(exposure_scale=3.0))
    msg = str(err.value)
    assert isinstance(err.value, RigError)
    assert '"kind": "board"' in msg and '"chart": [7, 5, 0.02]' in msg
    assert image_digest(other)[:12] in msg and "never projected in the recording" in msg
    assert '"exposure_scale": 3.0' in msg and "capture_lf" in msg
    assert "holds 4 capture(s) under this set-up, 0 of them with this projector image" in msg
    assert str(tmp_path / "rec") in msg and "is not in the recording" in msg
    assert replay.meta == {"scene": str(tmp_path / "rec" / "scene.toml"), "truth_seed": 7}

    replay.project(_pattern(255))                 # projected there, but not with this request
    with pytest.raises(ReplayError) as err:
        replay.capture_lf(LFCapture(exposure_scale=3.0))
    msg = str(err.value)
    assert "an image the recording projected" in msg and "4 of them with this projector image" in msg
    assert '"exposure_scale": 0.5' in msg          # what it does hold there is listed

    replay.setup(Collimator())
    with pytest.raises(ReplayError, match=r"capture_view .* holds 0 capture\(s\) under this set-up"):
        replay.capture_view()


def test_04_corrupt_or_missing_file_is_detected(tmp_path):
    _record(tmp_path / "rec")
    manifest = json.loads((tmp_path / "rec" / "manifest.json").read_text())
    lf = [e for e in manifest["events"] if e["event"] == "capture_lf"]
    assert ReplayRig(tmp_path / "rec").verify() == len({e["file"] for e in manifest["events"] if "file" in e})

    path = tmp_path / "rec" / lf[0]["file"]
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0x01
    path.write_bytes(bytes(data))
    replay = ReplayRig(tmp_path / "rec")
    with pytest.raises(ReplayError, match=rf"{lf[0]['file']} is corrupt or changed"):
        replay.capture_lf()
    with pytest.raises(ReplayError, match="corrupt"):
        replay.verify()

    (tmp_path / "rec" / lf[1]["file"]).unlink()
    replay = ReplayRig(tmp_path / "rec")
    replay.project(_pattern(0))
    with pytest.raises(ReplayError, match=rf"cannot read .*{lf[1]['file']}"):
        replay.capture_lf()


def test_05_manifest_is_complete_with_versions_and_hashes(tmp_path):
    import imageio.v3 as iio

    fake, answers = _record(tmp_path / "rec")
    folder = tmp_path / "rec"
    m = json.loads((folder / "manifest.json").read_text())
    assert m["format"] == "lftransfer-rig-recording" and m["version"] == 1 and m["complete"] is True
    assert set(m["versions"]) >= {"lftransfer", "numpy", "opencv", "mitsuba", "python"}
    assert all(m["versions"].values())
    assert m["info"]["kind"] == "fake" and m["info"]["lf_camera"] == [40, 32]
    assert m["meta"] == {"scene": str(folder / "scene.toml"), "truth_seed": 7}
    events = m["events"]
    assert [e["index"] for e in events] == list(range(len(events)))
    kinds = [e["event"] for e in events]
    assert kinds.count("capture_lf") == 16 and kinds.count("capture_view") == 5 and kinds.count("setup") == 5
    assert kinds.count("project") == 6
    board = next(e for e in events if e["event"] == "setup" and e["setup"]["kind"] == "board")
    assert setup_from_json(board["setup"]) == BOARD
    for e in events:
        if "file" in e:
            assert hashlib.sha256((folder / e["file"]).read_bytes()).hexdigest() == e["sha256"], e["file"]
    captures = [e for e in events if e["event"].startswith("capture")]
    assert all(e["file"].endswith(".png" if e["event"] == "capture_lf" else ".pfm") for e in captures)
    assert captures[0]["projected"] is None and captures[0]["request"] == describe(LFCapture())
    # each projector image stored once, viewable, as projected
    digests = {e["digest"] for e in events if e["event"] == "project"}
    assert len(list((folder / "projector").iterdir())) == len(digests) == 4
    assert np.array_equal(iio.imread(folder / "projector" / f"{image_digest(_pattern(50))[:16]}.png"),
                          _pattern(50))
    # the LF PNG is a 16-bit RGB image (colour type 2) of the codes as they are
    header, first = _png(folder / captures[0]["file"])
    assert header == (40, 32, 16, 2)
    assert first.dtype == np.uint16 and np.array_equal(first, answers[0].codes)
    # the view PFM reads the same (orientation, channel order, every bit) in another reader, Mitsuba's
    from lftransfer.backend import mitsuba

    view = next(e for e in captures if e["event"] == "capture_view")
    shown = np.array(mitsuba().Bitmap(str(folder / view["file"])))
    assert shown.dtype == np.float32 and shown.tobytes() == answers[7].radiance.tobytes()
    assert not list(folder.glob("**/.*"))                 # no temporary files left


@pytest.mark.parametrize("workers", [0, 2])
def test_06_interrupted_recording_is_readable(tmp_path, caplog, workers):
    folder = tmp_path / "rec"
    rig = RecordingRig(FakeRig(), folder, workers=workers)
    rig.project(_pattern(0))
    got = [rig.capture_lf(), rig.capture_lf(LFCapture(exposure_scale=2.0))]
    if workers:
        rig.flush()                                            # stored in the background: wait for it
    m = json.loads((folder / "manifest.json").read_text())    # written after every capture
    assert m["complete"] is False and [e["event"] for e in m["events"]] == ["project", "capture_lf", "capture_lf"]
    rig.setup(WhiteField())
    got.append(rig.capture_view())
    rig.flush()
    # no close(): the run died here

    with pytest.raises(ReplayError, match="incomplete"):
        ReplayRig(folder, strict=True)
    with caplog.at_level(logging.WARNING, logger="lftransfer.rig.replay"):
        replay = ReplayRig(folder)
    assert "incomplete" in caplog.text and "3 captures" in caplog.text
    replay.project(_pattern(0))
    assert _same(replay.capture_lf(), got[0])
    assert _same(replay.capture_lf(LFCapture(exposure_scale=2.0)), got[1])
    replay.setup(WhiteField())
    assert _same(replay.capture_view(), got[2])
    rig.close()
    assert json.loads((folder / "manifest.json").read_text())["complete"] is True


def test_07_missing_or_bad_manifest_names_the_folder(tmp_path):
    with pytest.raises(ReplayError, match=rf"{tmp_path / 'none'}: not a rig recording"):
        ReplayRig(tmp_path / "none")
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "manifest.json").write_text('{"format": "lftransfer-rig-recording", "version": 1, "eve')
    with pytest.raises(ReplayError, match=rf"{bad}: manifest.json unreadable"):
        ReplayRig(bad)
    (bad / "manifest.json").write_text('{"format": "something else"}')
    with pytest.raises(ReplayError, match="not a lftransfer-rig-recording manifest"):
        ReplayRig(bad)
    (bad / "manifest.json").write_text(json.dumps({"format": "lftransfer-rig-recording", "version": 2}))
    with pytest.raises(ReplayError, match="version 2"):
        ReplayRig(bad)
    _record(tmp_path / "rec")
    m = json.loads((tmp_path / "rec" / "manifest.json").read_text())
    del next(e for e in m["events"] if e["event"] == "capture_lf")["sha256"]
    (tmp_path / "rec" / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(ReplayError, match=r"malformed.*sha256"):
        ReplayRig(tmp_path / "rec")
    with pytest.raises(FileExistsError):
        RecordingRig(FakeRig(), tmp_path / "rec")


def test_08_replay_info_and_projector_checks(tmp_path):
    info16 = RigInfo(lf_camera=(30, 20), lf_camera_bits=16, projector=(12, 10), projector_bits=10, view=(16, 12),
                     kind="fake16")
    fake = FakeRig(info16)
    rig = RecordingRig(fake, tmp_path / "rec")
    image = _pattern(1000, info16)
    assert image.dtype == np.uint16
    rig.project(image)
    got = rig.capture_lf()
    with pytest.raises(ValueError, match="projector image"):
        rig.project(np.zeros((10, 12, 3), np.uint8))            # the inner rig refuses: nothing recorded
    rig.close()
    replay = ReplayRig(tmp_path / "rec")
    assert replay.info == RigInfo((30, 20), 16, (12, 10), 10, (16, 12), kind="replay")
    assert replay.recorded_info == info16
    with pytest.raises(ValueError, match="projector image"):
        replay.project(np.zeros((10, 12, 3), np.uint8))
    replay.project(image)
    assert _same(replay.capture_lf(), got)
    m = replay.manifest
    assert [e["event"] for e in m["events"]] == ["project", "capture_lf"]
    header, shown = _png(tmp_path / "rec" / m["events"][0]["file"])
    assert header == (12, 10, 16, 2) and np.array_equal(shown, image)
    replay.close()
    with pytest.raises(RigError, match="closed"):
        replay.capture_lf()


def test_09_storage_failure_is_raised_and_leaves_the_recording_incomplete(tmp_path, monkeypatch):
    folder = tmp_path / "rec"
    rig = RecordingRig(FakeRig(), folder)
    rig.capture_lf()
    rig.flush()
    real_store = replay_module._store

    def failing(path, a):
        if path.parent.name == "view":
            raise OSError("disk full")
        return real_store(path, a)

    monkeypatch.setattr(replay_module, "_store", failing)
    rig.capture_view()                                 # stored in the background: the failure comes later
    with pytest.raises(RigError, match="storing failed.*disk full"):
        for _ in range(10):
            rig.capture_lf()
            rig.flush()
    with pytest.raises(RigError, match="disk full"):
        rig.close()
    m = json.loads((folder / "manifest.json").read_text())
    assert m["complete"] is False and [e["event"] for e in m["events"]] == ["capture_lf"]


def test_10_unusual_answers_are_kept_exactly(tmp_path):
    fake = FakeRig(view_shape=(18, 24), lf_dtype=np.int32)   # not (H, W, 3) float32 / uint16: stored as .npy
    rig = RecordingRig(fake, tmp_path / "rec")
    got = [rig.capture_lf(), rig.capture_view()]
    rig.close()
    files = [e["file"] for e in rig._manifest["events"]]
    assert all(f.endswith(".npy") for f in files)
    replay = ReplayRig(tmp_path / "rec")
    assert _same(replay.capture_lf(), got[0]) and _same(replay.capture_view(), got[1])


_coord = st.floats(-0.5, 0.5, allow_nan=False, allow_infinity=False)
_pos = st.floats(1e-3, 1.0, allow_nan=False, allow_infinity=False)
# set-up *builders*: a replay gets the same set-up as its recording by building it from the same arguments
_setups = st.one_of(
    st.just(partial(RealScene)), st.just(partial(WhiteField)),
    st.builds(partial, st.just(FocalPlaneDiffuser), transmission=st.floats(0.0, 1.0)),
    st.builds(partial, st.just(Collimator), direction=st.tuples(_coord, _coord, _pos)),
    st.builds(partial, st.just(Board), centre=st.tuples(_coord, _coord, _pos), normal=st.tuples(_coord, _coord, _pos),
              size=st.tuples(_pos, _pos), albedo=st.floats(0.0, 1.0),
              chart=st.none() | st.tuples(st.integers(2, 20), st.integers(2, 20), _pos), point_light=st.booleans()),
    st.builds(partial, st.just(MirrorBall), centre=st.tuples(_coord, _coord, _pos), radius=_pos))
_requests = st.one_of(
    st.builds(LFCapture, exposure_scale=st.floats(1e-3, 1e3), frames=st.integers(1, 64)),
    st.builds(ViewCapture, frames=st.integers(1, 64), quality=st.none() | st.integers(1, 4096)))


def _close(a, b) -> bool:
    """Equal JSON data, floats to 1e-15 (a few ulp)."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_close(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(_close(x, y) for x, y in zip(a, b))
    if isinstance(a, float) and isinstance(b, float):
        return math.isclose(a, b, rel_tol=1e-15, abs_tol=1e-15)
    return a == b and type(a) is type(b)


@settings(max_examples=300, deadline=None)
@given(build=_setups, request=_requests, projected=st.none() | st.binary(min_size=1, max_size=8))
def test_11_describe_round_trip_and_request_key(build, request, projected):
    """What a replay relies on: describe() survives JSON exactly, a key is a pure function of the requests as
    built, and a manifest's set-up reads back as the same set-up (to the last bits: see test_12)."""
    setup = build()
    data = json.loads(json.dumps(describe(setup)))                   # as a manifest stores it
    assert data == describe(setup)
    again = setup_from_json(data)
    assert type(again) is type(setup) and _close(describe(again), data)
    digest = None if projected is None else hashlib.sha256(projected).hexdigest()
    key = request_key(setup, digest, request)
    assert request_key(build(), digest, request) == key
    assert json.loads(key) == {"setup": data, "projected": digest, "capture": describe(request)}


def test_12_setup_from_json_is_exact():
    s = Collimator(direction=(0.4355934636912273, 0.4441463831072985, 0.5))
    assert setup_from_json(describe(s)) == s


def test_13_killed_process_leaves_a_readable_recording(tmp_path):
    """A process killed while frames are still being written leaves a manifest that names only whole files."""
    import subprocess
    import sys
    from pathlib import Path

    folder = tmp_path / "rec"
    script = (
        "import os, sys\n"
        "from pathlib import Path\n"
        "from tests.rig.test_replay import FakeRig, RecordingRig, _pattern\n"
        "rig = RecordingRig(FakeRig(), Path(sys.argv[1]), workers=2)\n"
        "rig.project(_pattern(0))\n"
        "for _ in range(12):\n"
        "    rig.capture_lf(); rig.capture_view()\n"
        "os._exit(3)\n")
    root = Path(__file__).resolve().parents[2]
    done = subprocess.run([sys.executable, "-c", script, str(folder)], cwd=root, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 3, done.stderr
    replay = ReplayRig(folder)
    assert replay.manifest["complete"] is False
    replay.verify()                                         # every file the manifest names is whole
    fake = FakeRig()                                        # the same deterministic answers, in the same order
    fake.project(_pattern(0))
    replay.project(_pattern(0))
    for i in range(replay.captures):
        want = fake.capture_lf() if i % 2 == 0 else fake.capture_view()
        got = replay.capture_lf() if i % 2 == 0 else replay.capture_view()
        assert _same(got, want), i
    assert replay.remaining() == 0


def test_14_a_board_lit_by_the_point_light_records_and_replays(tmp_path):
    """The point light step's request (a board with the point light on, photographed with the projector black
    and white) is recorded and replayed bit for bit, apart from the same board with the light off; a board with
    the light off is described as before the field existed, so older recordings keep their keys."""
    lit = Board(centre=(0.0, 0.0, 0.08), normal=(0.4, 0.16, -0.9), size=(0.198, 0.154), chart=(7, 5, 0.022),
                point_light=True)
    dark = Board(centre=lit.centre, normal=lit.normal, size=lit.size, chart=lit.chart)
    assert "point_light" not in describe(dark) and describe(lit)["point_light"] is True
    assert setup_from_json(describe(lit)) == lit and setup_from_json(describe(dark)) == dark
    assert json.loads(request_key(dark, None, ViewCapture()))["setup"] == {
        "kind": "board", "centre": [0.0, 0.0, 0.08], "normal": list(dark.normal), "size": [0.198, 0.154],
        "albedo": 0.8, "chart": [7, 5, 0.022]}
    assert "point light ON" in lit.prompt() and "point light off" in dark.prompt()
    with pytest.raises(ValueError, match="point_light must be True or False"):
        Board(centre=(0.0, 0.0, 0.08), normal=(0.0, 0.0, 1.0), point_light="yes")
    # one of several lights: named in the description and the prompt; left out while None (all lights)
    second = Board(centre=lit.centre, normal=lit.normal, size=lit.size, chart=lit.chart, point_light=True, light=1)
    assert "light" not in describe(lit) and describe(second)["light"] == 1
    assert setup_from_json(describe(second)) == second and request_key(second, None, ViewCapture()) != \
        request_key(lit, None, ViewCapture())
    assert "switch point light 2 (in the scene file's order) ON and every other one off" in second.prompt()
    for bad, words in (({"light": -1}, "light's index >= 0"), ({"light": True}, "light's index >= 0"),
                       ({"light": 0, "point_light": False}, "but point_light is False")):
        with pytest.raises(ValueError, match=words):
            Board(**{"centre": (0.0, 0.0, 0.08), "normal": (0.0, 0.0, 1.0), "point_light": True, **bad})

    def session(rig):
        out = []
        for board in (lit, dark):
            rig.setup(board)
            for value in (0, 255):
                rig.project(np.full((INFO.projector[1], INFO.projector[0], 3), value, np.uint8))
                out.append(rig.capture_view(ViewCapture(quality=16)))
        return out

    rig = RecordingRig(FakeRig(), tmp_path / "rec")
    recorded = session(rig)
    rig.close()
    setups = [e["setup"] for e in json.loads((tmp_path / "rec" / "manifest.json").read_text())["events"]
              if e["event"] == "setup"]
    assert [s.get("point_light", False) for s in setups] == [True, False]
    replay = ReplayRig(tmp_path / "rec", strict=True)
    assert all(_same(a, b) for a, b in zip(recorded, session(replay)))
    assert not _same(recorded[0], recorded[2])                      # the light on and off are different requests
    replay = ReplayRig(tmp_path / "rec")
    replay.setup(Board(centre=lit.centre, normal=(0.0, 0.0, 1.0), point_light=True))
    with pytest.raises(ReplayError, match="not in the recording"):
        replay.capture_view(ViewCapture(quality=16))
