"""HardwareRig end to end on fakes: image-sequence cameras and the projector window under Xvfb."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from lftransfer.rig.base import Rig, RigError
from lftransfer.rig.hardware import HardwareRig, load_rig_file
from lftransfer.rig.hardware import projector as projector_module
from lftransfer.rig.requests import Board, LFCapture, RealScene, ViewCapture, WhiteField

from .conftest import SCREEN

LF = (40, 30)          # width, height
VIEW = (16, 12)


def _rig_file(tmp_path, lf_frames=12, view_frames=12, view_source="view/%03d.png"):
    rng = np.random.default_rng(7)
    (tmp_path / "lf").mkdir()
    (tmp_path / "view").mkdir()
    lf = [rng.integers(0, 4096, (LF[1], LF[0], 3), dtype=np.uint16) for _ in range(lf_frames)]
    view = [rng.integers(0, 256, (VIEW[1], VIEW[0], 3), dtype=np.uint8) for _ in range(view_frames)]
    for i, f in enumerate(lf):
        assert cv2.imwrite(str(tmp_path / "lf" / f"{i:04d}.png"), f[..., ::-1].copy())
    for i, f in enumerate(view):
        assert cv2.imwrite(str(tmp_path / "view" / f"{i:03d}.png"), f[..., ::-1].copy())
    path = tmp_path / "rig.toml"
    path.write_text(f"""
[lf_camera]
source = "lf/%04d.png"
width = {LF[0]}
height = {LF[1]}
bits = 12
frames = 2
timeout_s = 1.0

[view_camera]
source = "{view_source}"
width = {VIEW[0]}
height = {VIEW[1]}
response_gamma = [2.0, 1.0, 2.2]
radiance_scale = 4.0
timeout_s = 1.0

[projector]
width = {SCREEN[0]}
height = {SCREEN[1]}
settle_s = 0.01
drop_frames = 1
""")
    return path, lf, view


def test_01_end_to_end(tmp_path, display):
    path, lf, view = _rig_file(tmp_path)
    prompts: list[str] = []
    with HardwareRig(path, operator=prompts.append) as rig:
        assert isinstance(rig, Rig)
        assert rig.info.lf_camera == LF and rig.info.lf_camera_bits == 12 and rig.info.view == VIEW
        assert rig.info.projector == SCREEN and rig.info.kind == "hardware"

        # the operator is asked once per change; the rig starts in the real scene
        rig.setup(RealScene())
        assert prompts == []
        rig.setup(WhiteField())
        rig.setup(WhiteField())
        board = Board(centre=(0.0, 0.0, 0.08), normal=(0.0, 0.0, 1.0))
        rig.setup(board)
        rig.setup(Board(centre=(0.0, 0.0, 0.08), normal=(0.0, 0.0, 1.0)))
        lit = Board(centre=(0.0, 0.0, 0.08), normal=(0.0, 0.0, 1.0), point_light=True)    # the same board, light on
        rig.setup(lit)
        rig.setup(RealScene())
        assert prompts == [WhiteField().prompt(), board.prompt(), lit.prompt(), RealScene().prompt()]
        assert "switch the point light ON" in prompts[2] and "point light off" in prompts[1]

        image = np.random.default_rng(0).integers(0, 256, (SCREEN[1], SCREEN[0], 3), dtype=np.uint8)
        rig.project(image)
        assert np.abs(rig._projector.screenshot().astype(int) - image).max() <= 1
        with pytest.raises(ValueError, match="projector image"):
            rig.project(np.zeros((4, 4, 3), np.uint8))

        # drop 1 stale frame, average max(request 1, rig file 2) frames
        frame = rig.capture_lf()
        assert frame.codes.shape == (LF[1], LF[0], 3) and frame.codes.dtype == np.uint16
        assert frame.bits == 12 and frame.exposure_scale == 1.0
        expected = np.round((lf[1].astype(np.float64) + lf[2]) / 2).astype(np.uint16)
        assert np.array_equal(frame.codes, expected)
        frame = rig.capture_lf(LFCapture(frames=3))               # drop frame 3, average 4..6
        assert np.array_equal(frame.codes, np.round(np.mean([f.astype(np.float64) for f in lf[4:7]], 0)))

        with pytest.raises(RigError, match=r"LF camera \(.*lf/%04d\.png\): exposure bracketing \(exposure_scale "
                                            r"4\) is not supported by this camera.*capture_lf after projecting"):
            rig.capture_lf(LFCapture(exposure_scale=4.0))

        # view: each frame linearised, radiance_scale * (code / 255) ^ gamma, then averaged
        vf = rig.capture_view(ViewCapture(frames=2))
        gamma = np.array([2.0, 1.0, 2.2])
        lin = [4.0 * (f / 255.0) ** gamma for f in view[1:3]]
        assert vf.radiance.dtype == np.float32 and vf.radiance.shape == (VIEW[1], VIEW[0], 3)
        assert np.allclose(vf.radiance, (lin[0] + lin[1]) / 2, rtol=1e-5, atol=1e-6)
        vf = rig.capture_view(ViewCapture(quality=3))             # quality: the least number of frames
        lin = [4.0 * (f / 255.0) ** gamma for f in view[4:7]]
        assert np.allclose(vf.radiance, np.mean(lin, 0), rtol=1e-5, atol=1e-6)
    rig.close()                                                   # idempotent
    assert not projector_module._windows
    with pytest.raises(RigError, match="closed"):
        rig.capture_lf()


def test_02_set_up_without_an_operator(tmp_path, display):
    path, _, _ = _rig_file(tmp_path)
    with HardwareRig(load_rig_file(path)) as rig:
        rig.setup(RealScene())                                    # no change: nobody needs asking
        with pytest.raises(RigError, match=r"needs an operator.*white diffuser"):
            rig.setup(WhiteField())
        assert rig.current_setup == RealScene()                   # not remembered


def test_03_camera_that_runs_dry_and_one_that_cannot_open(tmp_path, display):
    path, _, _ = _rig_file(tmp_path, lf_frames=3)
    with HardwareRig(path, operator=lambda prompt: None) as rig:
        rig.project(np.zeros((SCREEN[1], SCREEN[0], 3), np.uint8))
        rig.capture_lf()                                          # frames 0 (dropped), 1, 2
        with pytest.raises(RigError, match=r"LF camera \(.*\): the recording ended after 3 frames during "
                                            r"capture_lf after projecting"):
            rig.capture_lf()
        rig.setup(WhiteField())
        with pytest.raises(RigError, match=r"view camera .*capture_view after the set-up white_field"):
            rig.capture_view(ViewCapture(frames=20))

    other = tmp_path / "other"
    other.mkdir()
    path, _, _ = _rig_file(other, view_source="missing.avi")
    with pytest.raises(RigError, match=r"view camera \(.*missing\.avi\): cannot open the camera"):
        HardwareRig(path)
    assert not projector_module._windows                          # the window opened first was closed again
