"""The quiet reference (lftransfer.sim.reference): the ground truth rendered in rounds until its noise on the cross
term is at most a third of the error it judges.

What each test shows:
- test_01: on a tiny run whose 16-sample ground truth is noisier than its error, the rounds meet the target; the
  noise falls as 1 / sqrt(samples) (the rounds are averaged by their samples, and only the objects' box gets
  them); a budget too small to meet it says so (met False).
- test_02: the rounds' blend is the samples-weighted mean inside the box and leaves the rest alone; the box holds
  every covered pixel, in whole blocks of the metrics' downsampling.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.small import write_tiny_scene


def tiny_run(tmp_path):
    """A tiny scene's transfer on its simulated rig: (the oracle, the judge of a quiet reference of its frame)."""
    from lftransfer.scenes import load_scene
    from lftransfer.settings import Overrides, resolve_settings
    from lftransfer.sim.metrics import composites
    from lftransfer.sim.oracle import open_simulated_rig
    from lftransfer.sim.reference import cross_term_judge
    from lftransfer.transfer.bounce import run_transfer

    scene = load_scene(write_tiny_scene(tmp_path / "tiny.toml", view=(64, 48)))
    rig, oracle = open_simulated_rig(scene, 3)
    result = run_transfer(rig, oracle.model, scene.synthetic_part(), resolve_settings(scene, Overrides()).transfer)
    return oracle, cross_term_judge(*composites(result))


def test_01_rounds_meet_the_noise_target(tmp_path):
    from lftransfer.sim.metrics import metric_factor
    from lftransfer.sim.reference import quiet_ground_truth

    oracle, judge = tiny_run(tmp_path)
    first = oracle.ground_truth(spp=16, use_cache=False)
    error0, noise0 = judge(first)
    assert noise0 > error0 / 3                              # the first round alone is too noisy to judge
    gt, ref = quiet_ground_truth(oracle.world, judge, spp=16, multiple=metric_factor(64), use_cache=False)
    assert ref.met and ref.rounds >= 2 and ref.spp > 16
    assert ref.noise <= ref.error / 3 and ref.ratio == pytest.approx(ref.noise / ref.error)
    assert (ref.error, ref.noise) == judge(gt)
    # the noise follows 1 / sqrt(samples): the rounds are averaged by their samples
    assert ref.noise == pytest.approx(noise0 * np.sqrt(16 / ref.spp), rel=0.3)
    x, y, w, h = ref.box
    assert w * h < 64 * 48 and ref.samples == 6 * 16 * 64 * 48 + 6 * (ref.spp - 16) * w * h
    poor, poor_ref = quiet_ground_truth(oracle.world, judge, spp=16, max_spp=32, use_cache=False)
    assert not poor_ref.met and poor_ref.spp == 32


def test_02_the_blend_and_the_box():
    from lftransfer.sim.ground_truth import GroundTruth
    from lftransfer.sim.reference import _blend, object_box

    rng = np.random.default_rng(0)

    def truth(h, w):
        return GroundTruth(*(rng.random((2, h, w, 3)).astype(np.float32) for _ in range(3)),
                           rng.random((h, w)).astype(np.float32), rng.random((h, w)).astype(np.float32))

    a = truth(12, 16)
    a.alpha_real[:] = 0
    a.alpha_synthetic[:] = 0
    a.alpha_real[5, 6] = 0.2
    a.alpha_synthetic[7, 9] = 1.0
    assert object_box(a) == (6, 5, 4, 3)
    assert object_box(a, 4) == (4, 4, 8, 4)
    box = (4, 4, 8, 4)
    b = truth(4, 8)
    c = _blend(a, 3, b, 1, box)
    assert np.allclose(c.union[:, 4:8, 4:12], 0.75 * a.union[:, 4:8, 4:12] + 0.25 * b.union)
    assert np.allclose(c.alpha_synthetic[4:8, 4:12], 0.75 * a.alpha_synthetic[4:8, 4:12] + 0.25 * b.alpha_synthetic)
    outside = np.ones((12, 16), bool)
    outside[4:8, 4:12] = False
    assert np.array_equal(c.real[:, outside], a.real[:, outside])
