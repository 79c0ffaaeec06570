"""Radiometric calibration against the simulated rig's hidden truth (quick fig4 scene)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from lftransfer.calibration.radiometric import (Radiometry, RadiometryError, VignettingPolynomial,
                                                calibrate_radiometry, response_error)
from lftransfer.lightfield import LightField, ResponseCurve
from lftransfer.scenes import quick_scene
from lftransfer.rig.model import nominal_rig
from lftransfer.rig.requests import FocalPlaneDiffuser, LFCapture
from lftransfer.sim.rig import SimRig
from lftransfer.sim.truth import Perturbation, perturbed_rig
from lftransfer.scenes import builtin_scene, load_scene

_CACHE: dict = {}


def _scene():
    return quick_scene(load_scene(builtin_scene("fig4")))


def _pipeline_model(scene, truth):
    """What the pipeline would hold before this step: true geometry (someone else's job), nominal radiometry."""
    nom = nominal_rig(scene.rig)
    return replace(truth,
                   camera=replace(truth.camera, response=nom.camera.response, exposure=nom.camera.exposure,
                                  vignetting=None),
                   projector=replace(truth.projector, response=nom.projector.response,
                                     max_radiance=nom.projector.max_radiance, cross_talk=None,
                                     black_level=(0.0, 0.0, 0.0)))


def _calibrated(variant, seed):
    """(scene, truth, model, radiometry, progress messages), calibrated once per variant and seed."""
    key = (variant, seed)
    if key not in _CACHE:
        scene = _scene()
        truth = perturbed_rig(scene.rig, seed)
        model = _pipeline_model(scene, truth)
        messages: list[str] = []
        result = calibrate_radiometry(SimRig(scene, truth=truth), model, scene, progress=messages.append)
        _CACHE[key] = (scene, truth, model, result, messages)
    return _CACHE[key]


def _lenslet_pixels(truth) -> np.ndarray:
    cam = truth.camera.device
    px = np.stack(np.meshgrid(np.arange(cam.width), np.arange(cam.height)), -1).reshape(-1, 2)
    k, _ = cam.pixel_to_ray(truth.array, px.astype(np.float64))
    return (k >= 0).reshape(cam.height, cam.width)


def test_01_response_error():
    a = ResponseCurve((1.0, 1.0, 1.0))
    assert response_error(a, a) == 0.0
    # max of sqrt(x) - x over [0, 1] is 1/4, at x = 1/4 (on the grid)
    assert response_error(a, ResponseCurve((1.0, 2.0, 1.0))) == pytest.approx(0.25, abs=1e-12)
    assert response_error(ResponseCurve((2.0, 2.0, 2.0)), a) == pytest.approx(0.25, abs=1e-12)


def test_02_vignetting_polynomial():
    terms = 15
    rng = np.random.default_rng(0)
    coeffs = np.zeros(terms)
    coeffs[0], coeffs[3], coeffs[5] = 1.0, -0.2, -0.1                 # 1 - 0.2 x^2 - 0.1 y^2
    coeffs[1:] += rng.normal(0, 0.01, terms - 1)
    poly = VignettingPolynomial(4, tuple(coeffs), (30, 40))
    m = poly.map()
    assert m.shape == (30, 40) and m.dtype == np.float32
    rows, cols = np.mgrid[0:30, 0:40]
    np.testing.assert_allclose(m, poly.evaluate(rows, cols), rtol=1e-6)
    assert VignettingPolynomial.from_json(json.loads(json.dumps(poly.to_json()))) == poly
    assert np.all(VignettingPolynomial(1, (-1.0, 0.0, 0.0), (3, 4)).map() == np.float32(0.05))   # floor
    with pytest.raises(ValueError, match="coefficients"):
        VignettingPolynomial(2, (1.0, 0.0), (3, 4))


def test_03_truth_draws_radiometric_deviations_on_their_own_generator():
    rig = _scene().rig
    nom = nominal_rig(rig)
    size = Perturbation()
    for seed in range(4):
        t = perturbed_rig(rig, seed)
        c = t.projector.cross_talk
        off = c[~np.eye(3, dtype=bool)]
        assert np.all((off >= 0) & (off <= size.cross_talk))
        assert np.all(np.abs(np.diag(c) - 1) <= size.channel_gain_rel)
        b = np.asarray(t.projector.black_level)
        assert np.all((b >= 0.2 * size.black_level) & (b <= size.black_level))
        assert abs(t.camera.exposure / nom.camera.exposure - 1) <= size.exposure_rel
        assert abs(t.projector.max_radiance / nom.projector.max_radiance - 1) <= size.brightness_rel
        # the other draws do not depend on the radiometric ones
        quiet = perturbed_rig(rig, seed, replace(size, cross_talk=0.0, black_level=0.0, exposure_rel=0.0,
                                                 brightness_rel=0.0, channel_gain_rel=0.0))
        assert quiet.array == t.array and quiet.tilt == t.tilt
        assert quiet.camera.response == t.camera.response and quiet.projector.response == t.projector.response
        np.testing.assert_array_equal(quiet.camera.device.homography, t.camera.device.homography)
        np.testing.assert_array_equal(quiet.projector.device.distortion, t.projector.device.distortion)
        np.testing.assert_array_equal(quiet.camera.vignetting, t.camera.vignetting)
        assert not quiet.projector.mixes_colours and quiet.camera.exposure == nom.camera.exposure


def test_04_focal_plane_exposure_scale(variant):
    scene = _scene()
    truth = perturbed_rig(scene.rig, 3)
    rig = SimRig(scene, truth=truth)
    rig.setup(FocalPlaneDiffuser())
    rig.project(np.full((*rig.projector_shape, 3), 200, np.uint8))
    g = np.asarray(truth.camera.response.gamma)
    lin = [((rig.capture_lf(LFCapture(exposure_scale=e)).codes / truth.camera.levels) ** g)[150:250, 200:300]
           .mean((0, 1)) for e in (1.0, 0.25)]
    np.testing.assert_allclose(lin[1] / lin[0], 0.25, rtol=0.01)
    with pytest.raises(ValueError, match="exposure_scale"):
        LFCapture(exposure_scale=0.0)


@pytest.mark.parametrize("seed", [0, 1])
def test_05_recovers_the_hidden_radiometry(variant, seed):
    scene, truth, model, r, messages = _calibrated(variant, seed)
    tc, tp = truth.camera, truth.projector
    assert response_error(r.camera_response, tc.response) <= 0.01
    assert response_error(r.projector_response, tp.response) <= 0.01
    # C is known up to scale (mean of its diagonal 1); black level and brightness on that scale
    s = np.mean(np.diag(tp.cross_talk))
    np.testing.assert_allclose(np.mean(np.diag(r.cross_talk)), 1.0, atol=1e-12)
    assert np.abs(r.cross_talk - tp.cross_talk / s).max() <= 0.01
    assert np.abs(r.black_level - np.asarray(tp.black_level) / s).max() <= 0.002
    assert abs(r.max_radiance / (tp.max_radiance * s) - 1) <= 0.02
    inside = _lenslet_pixels(truth)
    assert np.abs(r.vignetting[inside] / tc.vignetting[inside] - 1).max() <= 0.02
    assert r.camera_exposure == model.camera.exposure           # no action measures it (see the module)
    # progress per capture group, diagnostics for plots, JSON-ready
    assert len(messages) >= 4 and all(isinstance(m, str) for m in messages)
    d = r.diagnostics
    assert len(d["camera_response_samples"]) == 3 and len(d["projector_response_samples"]) == 3
    assert d["captures"]["board"] == 1 and d["captures"]["focal_plane"] <= 30
    json.dumps(d)


def test_06_apply_and_json_round_trip(variant):
    scene, truth, model, r, _ = _calibrated(variant, 0)
    back = Radiometry.from_json(json.loads(json.dumps(r.to_json())))
    np.testing.assert_array_equal(back.vignetting, r.vignetting)
    for name in ("camera_gamma", "projector_gamma", "cross_talk", "black_level"):
        np.testing.assert_array_equal(getattr(back, name), getattr(r, name))
    assert back.max_radiance == r.max_radiance and back.camera_exposure == r.camera_exposure
    assert "vignetting" in r.to_json() and "coeffs" in r.to_json()["vignetting"]
    m = back.apply(model)
    assert m.array is model.array and m.tilt == model.tilt
    assert m.camera.device is model.camera.device and m.projector.device is model.projector.device
    assert m.camera.response == r.camera_response and m.projector.response == r.projector_response
    np.testing.assert_array_equal(m.camera.vignetting, r.vignetting)
    np.testing.assert_array_equal(m.projector.cross_talk, r.cross_talk)
    assert m.projector.max_radiance == r.max_radiance and m.projector.black_level == tuple(r.black_level)
    with pytest.raises(ValueError, match="vignetting"):
        r.apply(nominal_rig(load_scene(builtin_scene("fig4")).rig))


def test_07_calibrated_encoder_emits_what_is_asked(variant):
    """Encoding with the calibrated model, emitting with the truth: colours right to about a percent."""
    scene, truth, model, r, _ = _calibrated(variant, 1)
    U = 16
    lf = LightField.zeros(truth.array, U, U)
    rng = np.random.default_rng(0)
    tp = truth.projector
    drive = 0.2 + 0.6 * rng.random(lf.data.shape)                     # well inside what the projector can do
    lf.data[:] = tp.max_radiance * (np.asarray(tp.black_level) + drive @ tp.cross_talk.T)
    truth_enc = truth.encoder(U, U)
    covered = truth_enc.codec.inv_norm3[..., 0] > 0
    target = truth_enc.codec.lightfield_to_image(lf)[covered]

    def error(m):
        emitted = truth_enc.emitted(m.encoder(U, U)(lf))[covered]
        return float(np.max(np.abs(emitted - target).mean(0) / target.mean(0)))   # worst channel

    calibrated = error(r.apply(model))
    assert calibrated < 0.01
    assert error(model) > 3 * calibrated                                 # nominal radiometry is visibly off


def test_08_nothing_seen_is_an_error():
    from tests.fakes import DarkRig

    scene = _scene()
    with pytest.raises(RadiometryError, match="camera response"):
        calibrate_radiometry(DarkRig(), nominal_rig(scene.rig), scene)
