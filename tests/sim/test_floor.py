"""The fidelity floor (lftransfer.sim.floor) on a tiny rig: the transpose of the projector's view render, the box
least squares and its bounds, the synthetic side's floor against the transfer's own machinery, the noise-corrected
score.

What each test shows:
- test_01: the adjoint render is the exact transpose of the forward render (<w, A t> = <A^T w, t> to float
  precision); with another seed it is not (the negative control: the test can fail); the projector image's light
  field through its linear drive (S d E^T) equals the rig's own, and its transpose pairs with it.
- test_02: on a target the projector can reach (A x0, x0 in the box) the fit drops the loss by orders of
  magnitude from the transfer's own projection; on the real cross term of a tiny run it never rises above the
  start and never goes below the non-negativity lower bound.
- test_03: the synthetic floor is the run's own synthetic side lit by the true light field (the same render, bit
  for bit), and the true light field carries the exchange (brighter than the real objects alone send).
- test_04: the noise-corrected score recovers a known error under noise three times its size; the plain score
  does not (the negative control).
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.small import write_tiny_scene


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A tiny scene, its simulated rig, oracle, settings, a 1-bounce transfer and a ground truth."""
    from lftransfer.scenes import load_scene
    from lftransfer.settings import Overrides, resolve_settings
    from lftransfer.sim.oracle import open_simulated_rig
    from lftransfer.transfer.bounce import run_transfer

    scene = load_scene(write_tiny_scene(tmp_path_factory.mktemp("floor") / "tiny.toml", view=(64, 48), gt_spp=32))
    rig, oracle = open_simulated_rig(scene, 3)
    settings = resolve_settings(scene, Overrides(bounces=1)).transfer
    result = run_transfer(rig, oracle.model, scene.synthetic_part(), settings)
    gt = oracle.ground_truth(spp=32, use_cache=False)
    return scene, rig, oracle, settings, result, gt


def test_01_the_adjoint_render_is_the_exact_transpose(tiny):
    from lftransfer.sim.floor import ProjectorOperator

    _, rig, *_ = tiny
    op = ProjectorOperator(rig)
    rng = np.random.default_rng(1)
    t = (rng.random(op.white.shape) * op.white).astype(np.float32)
    image = op.forward(t)
    assert image.max() > 0
    w = rng.standard_normal(image.shape).astype(np.float32)
    left = float(np.sum(w.astype(np.float64) * image))
    right = float(np.sum(op.adjoint(w).astype(np.float64) * t))
    assert abs(left - right) <= 1e-5 * np.sum(np.abs(w) * image)
    # negative control: the transpose of the render with other samples (another seed) does not pair with it
    rig._seed += 1
    try:
        wrong = float(np.sum(op.adjoint(w).astype(np.float64) * t))
    finally:
        rig._seed -= 1
    assert abs(left - wrong) > 1e-3 * np.sum(np.abs(w) * image)
    # the projector's pixels -> its light field: a projector image's light field through its linear drive, the
    # transpose of that map, and the drive quantised back to the same codes
    codes = rng.integers(0, 256, op.drive_shape).astype(np.uint8)
    np.testing.assert_allclose(op.lf_of_drive(op.drive_of(codes)), op.of_codes(codes), rtol=0, atol=2e-5)
    assert np.array_equal(op.codes_of_drive(op.drive_of(codes)), codes)
    d = rng.random(op.drive_shape).astype(np.float32)
    g = rng.standard_normal(op.black.shape).astype(np.float32)
    left, right = np.sum(op.lf_of_drive(d) * g.astype(np.float64)), np.sum(op.drive_adjoint(g) * d.astype(np.float64))
    assert abs(left - right) <= 1e-5 * np.sum(np.abs(op.lf_of_drive(d) * g))


def test_02_box_least_squares_reaches_a_reachable_target_and_keeps_its_bounds(tiny):
    from lftransfer.sim.floor import ProjectorOperator, box_least_squares, nonnegative_bound

    _, rig, _, _, result, gt = tiny
    op = ProjectorOperator(rig)
    start = np.clip(op.of_codes(result.projected_image), 0.0, op.white)
    rng = np.random.default_rng(2)
    x0 = (rng.random(op.white.shape) * op.white).astype(np.float32)
    target = op.forward(x0)
    fit = box_least_squares(op.forward, op.adjoint, target, start, op.white, iterations=30)
    assert all(b <= a for a, b in zip(fit.losses, fit.losses[1:]))                    # monotone
    assert fit.losses[-1] < 0.02 * fit.losses[0]
    assert np.all(fit.x >= 0) and np.all(fit.x <= op.white)
    # the real cross term of the run (the truth's first seed on the view's pixels)
    truth = gt.union[0] - gt.real[0] - gt.synthetic[0]
    alpha = gt.alpha_synthetic[..., None]
    target = np.where(alpha < 0.5, truth, 0.0).astype(np.float32)

    def apply(x):
        return np.where(alpha < 0.5, op.forward(x), 0.0)

    fit = box_least_squares(apply, lambda r: op.adjoint(np.where(alpha < 0.5, r, 0.0).astype(np.float32)),
                            target, start, op.white, iterations=15)
    bound = nonnegative_bound(apply, target, op.white)
    assert bound <= fit.losses[-1] <= fit.losses[0]
    assert fit.losses[-1] < fit.losses[0]
    assert bound > 0                           # noise below zero and the array's shadow: a bound with content


def test_03_the_synthetic_floor_is_the_transfers_own_side_lit_by_the_true_light_field(tiny):
    from lftransfer.sim.floor import fidelity_floor, true_incident_lightfield
    from lftransfer.transfer.synthetic_side import SyntheticSide

    scene, rig, oracle, settings, result, gt = tiny
    true_lf = true_incident_lightfield(rig, oracle.world, settings.angular_samples, seed=settings.seed)
    side = SyntheticSide(rig.truth, oracle.world.synthetic_part(), settings)
    lit = side.renderer.render_view(side.sensor, side.width, side.height,
                                    [side.incident_light(true_lf, settings.seed + 1)], spp=settings.view_spp,
                                    seed=settings.seed + 1000)
    # the real objects alone (no synthetic object to light them) send less: the true light field has the exchange
    alone = true_incident_lightfield(rig, oracle.world.model_copy(update={"synthetic": []}),
                                     settings.angular_samples, seed=settings.seed)
    assert true_lf.data.sum() > alone.data.sum() * 1.001
    floor = fidelity_floor(rig, oracle.world, result, gt, settings, iterations=5)
    assert floor.synthetic is not None and floor.real is not None
    from lftransfer.sim.floor import _Metric
    from lftransfer.sim.metrics import downsample

    m = _Metric.of(gt, result.real_view.shape[1], 256)
    a = result.synthetic_view.alpha[..., None]
    c = downsample(a * lit.rgb + (1 - a) * (result.real_view - result.real_view_direct), m.factor)
    assert floor.synthetic.floor == pytest.approx(m.score(c, m.covered & m.synthetic), rel=1e-9)
    assert floor.real.floor <= floor.real.transfer
    assert floor.floor == pytest.approx(np.hypot(floor.real.floor, floor.synthetic.floor))
    assert floor.transfer_over_floor == pytest.approx(floor.transfer / floor.floor)


def test_04_the_noise_corrected_score_sees_through_the_reference_noise():
    from lftransfer.sim.floor import _Metric

    rng = np.random.default_rng(4)
    shape = (200, 200, 3)
    truth = rng.random(shape)
    error = 0.05 * rng.standard_normal(shape)
    pair = [truth + 0.15 * rng.standard_normal(shape) for _ in range(2)]
    covered = np.ones(shape[:2], bool)
    m = _Metric(1, pair, covered, np.zeros(shape[:2], bool), float(np.sqrt(np.sum(truth ** 2))))
    expected = float(np.sqrt(np.sum(error ** 2))) / m.norm
    assert m.score(truth + error, covered) == pytest.approx(expected, rel=0.1)
    plain = float(np.sqrt(np.sum((truth + error - pair[1]) ** 2))) / m.norm
    assert plain > 2.5 * expected                                # the plain score is mostly the reference's noise
    assert m.noise(covered) == pytest.approx(0.15 * np.sqrt(truth.size) / m.norm, rel=0.05)
