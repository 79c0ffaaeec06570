"""The device twin's parts and the hardware rig's new fields, without processes or displays."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

from lftransfer.rig.base import RigError
from lftransfer.rig.hardware.stream import StreamCamera
from lftransfer.rig.hardware.config import RigFileError, parse_rig_file
from lftransfer.rig.hardware.operator import arranger
from lftransfer.rig.requests import Board, RealScene
from lftransfer.sim.twin.cameras import CameraTiming, planar

RIG = {"lf_camera": {"source": "http://127.0.0.1:9/lf", "width": 8, "height": 6, "bits": 12, "planar": True,
                     "control": "http://127.0.0.1:9/lf/control"},
       "view_camera": {"source": "http://127.0.0.1:9/view", "width": 8, "height": 6, "bits": 16, "planar": True},
       "projector": {"width": 8, "height": 6}}


def test_01_planar_frames_round_trip_through_the_camera_codes():
    """A (H, W, 3) image sent as stacked planes comes back bit for bit as the camera's codes."""
    config = parse_rig_file(RIG)
    rng = np.random.default_rng(1)
    image = rng.integers(0, 4096, (6, 8, 3)).astype(np.uint16)
    sent = planar(image)
    assert sent.shape == (18, 8) and sent.flags["C_CONTIGUOUS"]
    camera = StreamCamera(config.lf_camera, "LF camera")
    assert np.array_equal(camera.to_codes(sent), image.astype(np.float32))
    with pytest.raises(RigError, match="planar"):
        camera.to_codes(sent[:-1])                      # not three planes
    with pytest.raises(RigError, match="8x6"):
        camera.to_codes(planar(np.zeros((4, 8, 3), np.uint16)))


def test_02_stream_sources_and_new_fields_are_validated():
    config = parse_rig_file(RIG)
    assert config.lf_camera.kind == "stream" and config.lf_camera.live and config.operator.kind == "terminal"
    assert config.projector.stale_check and config.projector.x_display is None
    with pytest.raises(ValueError):
        StreamCamera(parse_rig_file(
            {**RIG, "lf_camera": {**RIG["lf_camera"], "source": 0}}).lf_camera)
    bad = {**RIG, "lf_camera": {**RIG["lf_camera"], "control": "ftp://x"}}
    with pytest.raises(RigFileError, match=r"lf_camera\.control: .*http"):
        parse_rig_file(bad, "rig.toml")
    with pytest.raises(RigFileError, match=r"operator.*url"):
        parse_rig_file({**RIG, "operator": {"kind": "http"}}, "rig.toml")
    with pytest.raises(RigFileError, match=r"operator\.kind"):
        parse_rig_file({**RIG, "operator": {"kind": "robot"}}, "rig.toml")


def test_03_camera_timing_stops_and_comes_back():
    t = CameraTiming(fps=7.0, stop_after_s=10.0, down_for_s=5.0)
    assert [t.down_at(s) for s in (0.0, 9.9, 10.0, 14.9, 15.0, 100.0)] == [False, False, True, True, False, False]
    forever = CameraTiming(fps=7.0, stop_after_s=1.0)
    assert forever.down_at(1e6) and not CameraTiming(fps=7.0).down_at(1e6)


def test_04_a_command_operator_gets_the_typed_set_up(tmp_path):
    """The command gets the set-up as JSON on its standard input; a failing command is a RigError naming it."""
    got = tmp_path / "got.json"
    script = tmp_path / "stage.py"
    script.write_text(f"import sys, pathlib; pathlib.Path({str(got)!r}).write_text(sys.stdin.read())\n")
    config = parse_rig_file({**RIG, "operator": {"kind": "command", "command": f"{sys.executable} {script}"}})
    arrange, endpoint = arranger(config.operator, lambda prompt: pytest.fail("the terminal was asked"))
    assert endpoint
    board = Board(centre=(0.0, 0.0, 0.1), normal=(0.0, 0.0, 1.0))
    arrange(board)
    message = json.loads(got.read_text())
    assert message["setup"]["kind"] == "board" and message["setup"]["centre"] == [0.0, 0.0, 0.1]
    assert message["prompt"] == board.prompt()
    failing = parse_rig_file({**RIG, "operator": {"kind": "command", "command": f"{sys.executable} -c 'exit(3)'"}})
    with pytest.raises(RigError, match="exit status 3"):
        arranger(failing.operator, print)[0](RealScene())
    asked = []
    terminal = arranger(parse_rig_file(RIG).operator, asked.append)
    terminal[0](board)
    assert asked == [board.prompt()] and not terminal[1]


def test_05_latency_read_from_the_median_less_half_a_frame():
    from lftransfer.rig.hardware.latency import LatencyResult

    r = LatencyResult(median_s=0.13, max_s=0.2, samples=(0.13,), black_level=0.0, marker_level=1.0, frame_s=0.1)
    assert r.latency_s == pytest.approx(0.08)
    assert r.to_json()["latency_s"] == pytest.approx(0.08) and r.to_json()["frame_s"] == 0.1
    unknown = LatencyResult(median_s=0.05, max_s=0.2, samples=(0.05,), black_level=0.0, marker_level=1.0)
    assert unknown.latency_s == 0.05


def test_06_stream_timestamps_date_a_frame_by_when_it_was_taken():
    """Frames stamped every 0.1 s by the camera arrive 20 ms later, except one that waited 0.4 s (a busy reader):
    dated by its stamp it stays 0.4 s old, dated by its arrival it would pass for a fresh one (the negative
    control). A stream whose stamps stop increasing (a frame counter, no timestamps) is dated by arrival."""
    from lftransfer.rig.hardware.stream import StreamClock

    clock = StreamClock()
    stamps = 5.0 + 0.1 * np.arange(10)             # the camera's clock, seconds
    arrivals = 100.0 + stamps + 0.02               # this machine's clock
    arrivals[6] += 0.4                             # frame 6 waited
    dates = [clock.date(p, a) for p, a in zip(stamps, arrivals)]
    assert not clock.unusable
    assert np.allclose(dates, 100.02 + stamps, atol=1e-9)
    assert all(b > a for a, b in zip(dates, dates[1:]))
    changed_at = 100.02 + stamps[6] + 0.2          # a change marked fresh from here: frame 6 is older than that
    assert dates[6] < changed_at < arrivals[6]
    late = StreamClock()           # the first frame waited: dates improve as quicker ones come, never going back
    assert late.date(0.0, 10.5) == 10.5 and late.date(0.1, 10.2) == pytest.approx(10.5, abs=1e-5)
    assert late.date(0.6, 10.7) == pytest.approx(10.7)
    counter = StreamClock()
    assert counter.date(0.0, 1.0) == 1.0 and counter.date(0.0, 1.1) == 1.1 and counter.unusable
    assert counter.date(1.0, 1.2) == 1.2                                       # stays on arrival
    counter.reset()
    assert not counter.unusable and counter.date(3.0, 4.0) == 4.0
    with pytest.raises(RigFileError, match=r"lf_camera.*timestamps.*stream URL"):
        parse_rig_file({**RIG, "lf_camera": {**RIG["lf_camera"], "source": "/dev/video0", "control": None,
                                             "timestamps": "stream"}}, "rig.toml")
    assert parse_rig_file({**RIG, "lf_camera": {**RIG["lf_camera"], "timestamps": "stream"}}).lf_camera.timestamps \
        == "stream"
