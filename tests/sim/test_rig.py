"""The simulated rig: what its LF camera sees follows the window model; it honours the Rig protocol."""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.rig.base import Rig
from lftransfer.rig.model import nominal_rig
from lftransfer.sim.rig import SimRig
from lftransfer.scenes.format import SceneConfig


def _scene(sphere_at=(0.01, -0.008, 0.09), intensity=1.0):
    return SceneConfig.model_validate({
        "rig": {"lattice": "rect", "rows": 3, "cols": 3, "lf_camera": [300, 300], "projector": [150, 150],
                "angular_samples": 16, "read_noise": 0.0, "full_well": 1e9},
        "view": {"resolution": [64, 48], "origin": [0.5, 0.1, 0.0], "target": [0, 0, 0]},
        "light": {"position": [0.0, 0.0, 0.02], "intensity": [intensity] * 3},
        "real": [{"name": "ball", "shape": "sphere", "radius": 0.004, "translate": list(sphere_at),
                  "material": {"type": "diffuse", "albedo": [0.9, 0.9, 0.9]}}],
        "synthetic": [],
    })


def test_01_protocol_and_bad_projector_image(variant):
    rig = SimRig(_scene(), capture_spp=1)
    assert isinstance(rig, Rig)
    with pytest.raises(ValueError, match="projector image"):
        rig.project(np.zeros((10, 10, 3), np.uint8))
    frame = rig.capture_lf()
    raw = frame.codes
    assert frame.bits == 12 and rig.info.projector_shape == (150, 150)
    assert raw.shape == (300, 300, 3) and raw.dtype == np.uint16 and raw.max() < 4096


def test_02_captured_direction_points_at_the_object(variant):
    """In every lenslet the captured light comes from the direction of the lenslet centre towards the small
    sphere: the centroid of the (aperture-blurred) blob is that direction."""
    scene = _scene()
    rig = SimRig(scene, capture_spp=16)
    model = nominal_rig(scene.rig)
    lf = model.decoder(16, 16)(rig.capture_lf().codes)
    target = np.array([0.01, -0.008, 0.09])
    step = 2 * model.array.half_width / 16
    uu, vv = np.meshgrid(lf.u, lf.v)
    for k in range(model.array.K):
        w = lf.data[k].sum(-1)
        w = np.where(w > 0.2 * w.max(), w, 0.0)
        d = target - np.append(model.array.centres[k], 0.0)
        u, v = d[0] / d[2], d[1] / d[2]
        if max(abs(u), abs(v)) > 0.5 - 0.15:    # blob cut by the edge of the angular window
            continue
        cu, cv = (w * uu).sum() / w.sum(), (w * vv).sum() / w.sum()
        assert abs(cu - u) < 0.5 * step and abs(cv - v) < 0.5 * step, (k, cu, u, cv, v)


def test_03_projected_light_reaches_the_real_scene(variant):
    """A projected light field makes the real scene brighter; black projection changes nothing."""
    scene = _scene(intensity=0.01)
    rig = SimRig(scene, capture_spp=1)
    black = np.zeros((150, 150, 3), np.uint8)
    rig.project(black)
    a = rig.capture_lf().codes.astype(float)
    rig.project(black)
    b = rig.capture_lf().codes.astype(float)
    rig.project(np.full((150, 150, 3), 255, np.uint8))
    c = rig.capture_lf().codes.astype(float)
    assert np.abs(a - b).max() <= 1            # same world, only quantisation
    assert c.sum() > 1.2 * a.sum()
