"""Projector-to-camera mapping by Gray codes, through the simulated rig's hidden truth."""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.calibration.projector import decode_gray_code, fit_projector_camera, gray_code_patterns
from lftransfer.optics.geometry import apply_homography
from lftransfer.rig.requests import FocalPlaneDiffuser
from lftransfer.sim.rig import SimRig
from lftransfer.sim.truth import perturbed_rig
from lftransfer.scenes import builtin_scene, load_scene, with_overrides


def test_01_gray_code_round_trip():
    w, h = 37, 20
    pats = gray_code_patterns(w, h)
    assert len(pats) == 2 * (6 + 5) and pats[0].shape == (h, w) and pats[0].dtype == np.uint8
    col, row, valid = decode_gray_code([p.astype(float) / 255 for p in pats], w, h)
    yy, xx = np.mgrid[0:h, 0:w]
    assert valid.all() and np.array_equal(col, xx) and np.array_equal(row, yy)
    # adjacent codes differ in exactly one pattern (Gray code)
    stack = np.stack([p[0] for p in pats[0:12:2]])
    assert np.all((stack[:, 1:] != stack[:, :-1]).sum(axis=0) == 1)
    with pytest.raises(ValueError, match="captures"):
        decode_gray_code(pats[:3], w, h)


@pytest.mark.parametrize("seed", [0, 1])
def test_02_recovers_hidden_mapping(variant, seed):
    """From the rig's images alone, the camera -> projector mapping is found to well under 0.5 projector pixel."""
    scene = with_overrides(load_scene(builtin_scene("fig4")),
                           rig={"rows": 4, "cols": 5, "lf_camera": [480, 360], "projector": [240, 180],
                                "angular_samples": 12})
    truth = perturbed_rig(scene.rig, seed)
    rig = SimRig(scene, truth=truth, capture_spp=1)
    h, w = rig.projector_shape
    rig.setup(FocalPlaneDiffuser())
    captures = []
    for p in gray_code_patterns(w, h):
        rig.project(np.repeat(p[..., None], 3, axis=2))
        captures.append(rig.capture_lf().codes.astype(np.float64)[..., 1] / 4095)
    col, row, valid = decode_gray_code(captures, w, h)
    fit = fit_projector_camera(col, row, valid)
    # Truth: camera pixel -> focal plane -> projector pixel.
    cam, prj = truth.camera.device, truth.projector.device
    ys, xs = np.nonzero(valid)
    xy = np.stack([xs, ys], 1)[:: 7].astype(np.float64)
    true = apply_homography(prj.homography @ np.linalg.inv(cam.homography), xy)
    err = np.linalg.norm(fit.camera_to_projector(xy) - true, axis=1)
    assert np.sqrt(np.mean(err ** 2)) < 0.1
    assert 0.3 < fit.rms_px < 0.6          # the codes' own one-pixel quantisation
