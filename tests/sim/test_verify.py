"""Metrics against ground truth: undefined metrics are None with a reason (strict JSON), and a ground truth too
noisy for the error it measures is named with the samples that would resolve it."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from lftransfer.composite import composite
from lftransfer.imageio_utils import strict_json
from lftransfer.sim.ground_truth import GroundTruth
from lftransfer.sim.metrics import (IDENTICAL, NO_CROSS, NO_LIGHT, NO_PIXELS, Evaluation, evaluate, gt_noise_verdict,
                                    negative_control, object_mask)

H, W = 12, 16


class _Views(SimpleNamespace):
    """A transfer result's views, composited with the over operator (what evaluate reads of a result)."""

    def composite(self):
        return composite(self.synthetic_view.rgb, self.synthetic_view.alpha, self.real_view)

    def composite_direct(self):
        return composite(self.bounces[0].synthetic_view.rgb, self.synthetic_view.alpha, self.real_view_direct)


def _result(real, synthetic, alpha):
    view = SimpleNamespace(rgb=synthetic, alpha=alpha)
    return _Views(real_view=real, real_view_direct=real, synthetic_view=view,
                  bounces=[SimpleNamespace(synthetic_view=view)])


def _gt(union, real, synthetic, alpha_real, alpha_synthetic):
    return GroundTruth(union=np.stack([union, union]), real=np.stack([real, real]),
                       synthetic=np.stack([synthetic, synthetic]), alpha_real=alpha_real,
                       alpha_synthetic=alpha_synthetic)


def _strict(metrics) -> dict:
    text = json.dumps(strict_json(metrics.to_json()), allow_nan=False)
    return json.loads(text)


def test_01_black_scene_every_metric_is_null_with_a_reason():
    zero, ones = np.zeros((H, W, 3), np.float32), np.ones((H, W), np.float32)
    m = evaluate(_result(zero, zero, ones), _gt(zero, zero, zero, ones, ones))
    for key in ("psnr_db", "psnr_db_direct_only", "psnr_objects_db", "psnr_objects_db_direct_only",
                "gt_noise_psnr_db", "cross_transfer_rel_error", "cross_gt_noise_rel", "cross_term_rel_size"):
        assert getattr(m, key) is None and m.undefined[key], key
    assert m.undefined["psnr_db"] == NO_LIGHT and m.undefined["cross_transfer_rel_error"] == NO_CROSS
    assert m.undefined["psnr_objects_db"] == NO_LIGHT
    assert _strict(m)["psnr_db"] is None


def test_02_no_cross_term_synthetic_objects_only():
    rng = np.random.default_rng(0)
    syn = rng.random((H, W, 3)).astype(np.float32)
    zero = np.zeros((H, W, 3), np.float32)
    alpha = np.ones((H, W), np.float32)
    noisy = syn + 0.01
    m = evaluate(_result(zero, noisy, alpha), _gt(syn, zero, syn, np.zeros((H, W), np.float32), alpha))
    assert m.psnr_db is not None and np.isfinite(m.psnr_db)
    assert m.cross_transfer_rel_error is None and m.undefined["cross_transfer_rel_error"] == NO_CROSS
    assert m.undefined["gt_noise_psnr_db"] == IDENTICAL       # two identical ground truths
    _strict(m)


def _noise(noise, error):
    """An evaluation with only the two numbers the noise verdict reads."""
    return Evaluation(None, None, None, None, error, None, noise, None, (1, 1), 1, {})


def test_03_noise_verdict_names_the_samples_that_would_resolve_it():
    verdict = gt_noise_verdict(_noise(0.33, 0.26), 128)
    assert verdict is not None and verdict.spp_needed == 4096      # 128 * (0.33 / (0.25 * 0.26))^2 = 3299 -> 4096
    assert "--gt-spp 4096" in verdict.message() and "0.33" in verdict.message()
    assert gt_noise_verdict(_noise(0.1, 0.26), 128) is None
    assert gt_noise_verdict(_noise(None, 0.26), 128) is None
    big = gt_noise_verdict(_noise(0.2, 0.39), 64)
    assert big is not None and big.spp_needed >= 128                # always more than the run had


def test_04_psnr_over_the_objects_sees_what_the_black_background_hides():
    """The same error on the objects' pixels: the full-frame PSNR is raised by the background's pixels that
    match exactly, the PSNR over the objects is not; both use the ground truth's peak and the cross error's mask."""
    zero = np.zeros((H, W, 3), np.float32)
    alpha = np.zeros((H, W), np.float32)
    alpha[4:8, 6:10] = 1.0                                        # 16 of 192 pixels show the object
    on_object = np.repeat(alpha[..., None], 3, axis=-1)
    truth = (0.5 * on_object).astype(np.float32)
    truth[5, 7] = 1.0                                             # the peak
    image = (truth + 0.01 * on_object).astype(np.float32)        # off by 0.01 on the object only
    m = evaluate(_result(zero, image, alpha), _gt(truth, zero, truth, np.zeros((H, W), np.float32), alpha))
    assert m.psnr_objects_db == pytest.approx(40.0)            # 10 log10(1 / 0.01^2)
    assert m.psnr_objects_db_direct_only == pytest.approx(40.0)
    assert m.psnr_db == pytest.approx(40.0 + 10 * np.log10(H * W / 16))      # 50.8 dB: flattered by 10.8 dB
    assert m.metric_pixels == 16 and object_mask(_gt(truth, zero, truth, alpha, alpha), 1).sum() == 16
    # half the object's coverage in a 2 x 2 block still counts the block as the object's
    half = np.zeros((H, W), np.float32)
    half[4, 6] = 0.5
    assert object_mask(_gt(truth, zero, truth, half, np.zeros((H, W), np.float32)), 2).sum() == 1


def test_05_no_object_in_view_psnr_over_objects_is_null_with_a_reason():
    rng = np.random.default_rng(1)
    background = rng.random((H, W, 3)).astype(np.float32)
    zero, none = np.zeros((H, W, 3), np.float32), np.zeros((H, W), np.float32)
    m = evaluate(_result(background + 0.01, zero, none), _gt(background, background, zero, none, none))
    assert np.isfinite(m.psnr_db)
    for key in ("psnr_objects_db", "psnr_objects_db_direct_only"):
        assert getattr(m, key) is None and m.undefined[key] == NO_PIXELS, key
    assert _strict(m)["psnr_objects_db"] is None


def test_06_negative_control_margins_and_verdict():
    """A control that misses more of the cross term is measurably worse (against the ground truth and each of its
    seeds); one that misses as much is not, and says so."""
    rng = np.random.default_rng(2)
    none = np.zeros((H, W), np.float32)
    a_real, a_syn = none.copy(), none.copy()
    a_real[2:6, 2:8], a_syn[6:10, 8:14] = 1.0, 1.0
    real = (0.4 * np.repeat(a_real[..., None], 3, -1)).astype(np.float32)
    syn = (0.3 * np.repeat(a_syn[..., None], 3, -1)).astype(np.float32)
    cross = (0.05 * rng.random((H, W, 3)) * a_real[..., None]).astype(np.float32)    # the cube's light on the block
    seeds = [real + syn + cross + 0.002 * rng.standard_normal((H, W, 3)).astype(np.float32) for _ in range(2)]
    gt = GroundTruth(union=np.stack(seeds), real=np.stack([real, real]), synthetic=np.stack([syn, syn]),
                     alpha_real=a_real, alpha_synthetic=a_syn)

    def run(k: float):
        """A transfer that recovers k times the cross term."""
        view = SimpleNamespace(rgb=syn, alpha=a_syn)
        return _Views(real_view=real + k * cross, real_view_direct=real, synthetic_view=view,
                      bounces=[SimpleNamespace(synthetic_view=view)])

    worse = negative_control(run(0.9), run(0.4), gt, "nominal (rig file)")
    assert worse.measurably_worse
    assert worse.cross_error_margin == pytest.approx(0.5, abs=0.05)
    assert worse.psnr_objects_margin_db > 3 and all(m > 3 for m in worse.psnr_objects_margin_db_per_gt)
    assert worse.cross_transfer_rel_error == pytest.approx(evaluate(run(0.4), gt).cross_transfer_rel_error)
    entry = json.loads(json.dumps(worse.to_json(), allow_nan=False))
    assert entry["rig_model"] == "nominal (rig file)" and len(entry["cross_error_margin_per_gt"]) == 2
    # as far off as the run, on the other side: not measurably worse, and the message says so
    blind = negative_control(run(0.9), run(1.1), gt, "nominal (rig file)")
    assert not blind.measurably_worse and "not measurably worse" in blind.message()
    # no object in view: the margins are undefined and the control is not called worse
    empty = GroundTruth(union=gt.union, real=gt.real, synthetic=gt.synthetic, alpha_real=none, alpha_synthetic=none)
    undefined = negative_control(run(0.9), run(0.4), empty, "nominal (rig file)")
    assert not undefined.measurably_worse and undefined.psnr_objects_margin_db is None
    assert "undefined" in undefined.message()


def test_07_cross_transfer_error_of_any_composite_agrees_with_evaluate():
    """The cross error of two composites (a live frame and the no-exchange composite) is evaluate's figure for
    the same images, 0 for a transfer that adds exactly the ground truth's cross term; None without one."""
    from lftransfer.sim.metrics import cross_transfer_error

    rng = np.random.default_rng(3)
    real, syn = (rng.random((H, W, 3)).astype(np.float32) for _ in range(2))
    alpha = (rng.random((H, W)) > 0.5).astype(np.float32)
    syn *= alpha[..., None]
    extra = 0.1 * rng.random((H, W, 3)).astype(np.float32)
    none = composite(syn, alpha, real)
    gt = _gt(none + extra, real, syn, 1 - alpha, alpha)
    lit = real + 0.8 * extra
    view = SimpleNamespace(rgb=syn, alpha=alpha)
    result = _Views(real_view=lit, real_view_direct=real, synthetic_view=view,
                    bounces=[SimpleNamespace(synthetic_view=view)])
    expected = evaluate(result, gt)
    check = cross_transfer_error(composite(syn, alpha, lit), none, gt)
    assert check.error == pytest.approx(expected.cross_transfer_rel_error, rel=1e-6) and check.error > 0.1
    assert check.gt_noise == expected.cross_gt_noise_rel == 0.0          # the two seeds are the same here
    assert check.by_side == expected.cross_by_side                       # the same split as evaluate's
    assert check.by_side["real"].rel_error == pytest.approx(0.2, rel=1e-5)   # 80 % of the exchange reached them
    assert cross_transfer_error(none + extra, none, gt).error == pytest.approx(0.0, abs=1e-6)
    assert cross_transfer_error(none + extra, none, _gt(none, real, syn, 1 - alpha, alpha)).error is None


def test_08_cross_by_side_splits_where_the_error_is():
    """The split by side: a transfer that is exact on the synthetic objects and gives 80 % of the light on the real
    ones has error 0 and energy ratio 1 there, 0.2 and 0.8 here, and no error left after the best scale (a pure
    energy loss); a wrong shape of the same energy keeps its error after scaling. The two halves' squared errors
    add up to the whole cross error's."""
    from lftransfer.sim.ground_truth import GroundTruth
    from lftransfer.sim.metrics import cross_by_side, object_mask

    rng = np.random.default_rng(3)
    h, w = 8, 12
    alpha_syn = np.zeros((h, w), np.float32)
    alpha_syn[:, :5] = 1
    alpha_real = np.zeros((h, w), np.float32)
    alpha_real[:, 5:] = 1
    c = rng.uniform(0.5, 1.0, (h, w, 3)).astype(np.float32)
    noise = 1e-3 * rng.standard_normal((h, w, 3)).astype(np.float32)
    both = np.stack([c, c])
    gt = GroundTruth(union=both, real=both, synthetic=both, alpha_real=alpha_real, alpha_synthetic=alpha_syn)
    pair = [c + noise, c - noise]
    lft = c.copy()
    lft[:, 5:] *= 0.8
    covered, synthetic = object_mask(gt, 1), alpha_syn > 0.5
    split = cross_by_side(lft, pair, covered, synthetic)
    assert split["synthetic"].rel_error == pytest.approx(0, abs=1e-6) and split["synthetic"].energy_ratio == \
        pytest.approx(1)
    assert split["real"].rel_error == pytest.approx(0.2, rel=1e-4) and split["real"].energy_ratio == \
        pytest.approx(0.8, rel=1e-5)
    assert split["real"].rel_error_shape == pytest.approx(0, abs=1e-5)
    assert split["real"].pixels == 7 * h and split["synthetic"].pixels == 5 * h
    assert 0 < split["real"].gt_noise_rel < 0.01
    flipped = c.copy()
    flipped[:, 5:] = c[:, 5:][:, ::-1]                       # the same light, in the wrong places
    assert cross_by_side(flipped, pair, covered, synthetic)["real"].rel_error_shape > 0.1
    total = np.sqrt(np.sum((lft - c) ** 2) / np.sum(c ** 2))
    parts = [split[s].rel_error ** 2 * np.sum(c[m] ** 2) for s, m in (("real", alpha_real > 0), ("synthetic", alpha_syn > 0))]
    assert np.sqrt(sum(parts) / np.sum(c ** 2)) == pytest.approx(total, rel=1e-5)


def test_ground_truth_of_a_point_light_and_an_emitter_renders_each_alone(variant, monkeypatch):
    """A point light and an emitting object together: the ground truth renders each source alone and adds the
    images (transport is linear in the sources). The same image as one render of both, far less noise on the
    cross term (one render picks one source per light sample, a noise the sides alone do not share)."""
    import numpy as np

    import lftransfer.sim.ground_truth as g
    from lftransfer.sim.metrics import cross_term_truth, object_mask
    from tests.transfer.test_interfaces import _corner

    scene = _corner(lamp=True)
    assert len(g._light_groups(scene)) == 2 and len(g._light_groups(scene.synthetic_part())) == 2

    def noise(gt) -> float:
        pair, mask = cross_term_truth(gt, 1), object_mask(gt, 1)
        return float(np.linalg.norm((pair[0] - pair[1])[mask]) / np.linalg.norm((pair[0] + pair[1])[mask] / 2))

    apart = g.render_ground_truth(scene, spp=256, use_cache=False)
    monkeypatch.setattr(g, "_light_groups", lambda s: [(list(s.lights), True)])       # one render of both
    together = g.render_ground_truth(scene, spp=256, use_cache=False)
    both = (apart.alpha_real + apart.alpha_synthetic) > 0
    for name in ("union", "real", "synthetic"):
        a, b = getattr(apart, name).mean(0)[both], getattr(together, name).mean(0)[both]
        assert abs(a.sum() / b.sum() - 1) < 0.01, name
    assert noise(apart) < 0.5 * noise(together)
