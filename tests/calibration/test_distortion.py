"""Lenslet distortion from a tilted collimator: the fit, and the sweep through the simulated rig."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from lftransfer.calibration.distortion import calibrate_distortion, collimator_directions, fit_distortion
from lftransfer.scenes import quick_scene
from lftransfer.rig.model import nominal_rig
from lftransfer.sim.rig import SimRig
from lftransfer.sim.truth import perturbed_rig
from lftransfer.scenes import builtin_scene, load_scene


def test_01_fit_recovers_coefficients_and_mount_angle():
    """Noiseless (x_n, x_d) pairs of known k1, k2 and a turned mount give them back exactly."""
    rng = np.random.default_rng(3)
    K = 7
    coef = np.stack([rng.uniform(-0.08, 0.0, K), rng.uniform(-0.01, 0.01, K)], 1)
    phi = np.radians(1.3)
    d = collimator_directions(0.35, 5)
    xn = -d[:, :2] / d[:, 2:3]
    k = np.repeat(np.arange(K), len(xn))
    xn_all = np.tile(xn, (K, 1))
    rot = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
    xr = xn_all @ rot.T
    r2 = np.sum(xr ** 2, 1)
    xd = xr * (1 + coef[k, 0] * r2 + coef[k, 1] * r2 ** 2)[:, None]
    fit = fit_distortion(k, xn_all, xd, K, iterations=20)
    np.testing.assert_allclose(fit.coefficients, coef, atol=1e-6)
    assert abs(fit.mount_angle - phi) < 1e-7 and fit.rms < 1e-8
    assert np.all(fit.spots == len(xn))


def test_02_sweep_recovers_hidden_distortion(variant):
    """Through the simulated rig (quarter resolution), per-lenslet k1 within 0.01 of the hidden truth and the
    mount angle equal to minus the array's hidden rotation (the model frame is the nominal, unrotated lattice)."""
    scene = quick_scene(load_scene(builtin_scene("fig4")))
    truth = perturbed_rig(scene.rig, 2)
    rig = SimRig(scene, truth=truth)
    nominal = nominal_rig(scene.rig).array
    # the LF camera's homography in the model frame, as the lenslet centres give it
    t = truth.array
    s, th = t.pitch / nominal.pitch, t.rotation
    sim = np.array([[s * np.cos(th), -s * np.sin(th), t.offset[0]], [s * np.sin(th), s * np.cos(th), t.offset[1]],
                    [0, 0, 1]])
    device = replace(truth.camera.device, homography=truth.camera.device.homography @ sim)
    fit = calibrate_distortion(rig, nominal, device, truth.camera.levels)
    err = fit.coefficients[:, 0] - truth.camera.device.distortion[:, 0]
    assert np.sqrt(np.mean(err ** 2)) < 0.01
    assert abs(fit.mount_angle + th) < np.radians(0.1)
