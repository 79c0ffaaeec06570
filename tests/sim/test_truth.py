"""Hidden truths of the simulated rig: deviations within their stated sizes; the collimated-source image."""

from __future__ import annotations

import numpy as np

from lftransfer.rig.model import nominal_rig
from lftransfer.rig.requests import Collimator
from lftransfer.sim.rig import SimRig
from lftransfer.sim.truth import Perturbation, perturbed_rig
from lftransfer.scenes import builtin_scene, load_scene, with_overrides


def _scene():
    return with_overrides(load_scene(builtin_scene("fig4")),
                          rig={"rows": 4, "cols": 5, "lf_camera": [400, 300], "projector": [200, 150],
                               "angular_samples": 12})


def test_01_deviations_within_sizes_and_seeded():
    rig = _scene().rig
    size = Perturbation()
    a, b, c = perturbed_rig(rig, 1), perturbed_rig(rig, 1), perturbed_rig(rig, 2)
    assert a.array == b.array and a.array != c.array
    assert abs(np.degrees(a.array.rotation)) <= size.rotation_deg
    assert max(abs(np.asarray(a.array.offset))) <= size.offset_m
    assert abs(a.array.pitch / rig.pitch - 1) <= size.pitch_rel
    nominal = nominal_rig(rig)
    assert not np.allclose(a.camera.device.homography, nominal.camera.device.homography)
    assert np.all(np.abs(a.camera.device.distortion[:, 0] - size.k1_mean) <= size.k1)
    vig = a.camera.vignetting
    assert vig[vig.shape[0] // 2, vig.shape[1] // 2] > 0.99 and vig[0, 0] < 1 - 0.9 * size.vignetting


def test_02_collimated_source_images_lenslet_centres(variant):
    scene = _scene()
    truth = perturbed_rig(scene.rig, 5)
    rig = SimRig(scene, truth=truth, capture_spp=1)
    rig.setup(Collimator())
    img = rig.capture_lf().codes.astype(np.float64)[..., 1]
    spots = truth.camera.device.ray_to_pixel(truth.array, np.arange(truth.array.K),
                                             np.tile([0.0, 0.0, 1.0], (truth.array.K, 1)))
    errors = []
    for x, y in spots:
        if not (4 <= x < img.shape[1] - 5 and 4 <= y < img.shape[0] - 5):
            continue
        ys, xs = np.mgrid[int(y) - 4:int(y) + 6, int(x) - 4:int(x) + 6]
        w = np.clip(img[ys, xs] - np.median(img), 0, None)
        errors.append(np.hypot((w * xs).sum() / w.sum() - x, (w * ys).sum() / w.sum() - y))
    assert len(errors) >= 0.8 * truth.array.K
    assert np.sqrt(np.mean(np.square(errors))) < 0.1
