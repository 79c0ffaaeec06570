"""Metrics against ground truth: undefined metrics are None with a reason (strict JSON), and a ground truth too
noisy for the error it measures is named with the samples that would resolve it."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np

from lftransfer.imageio_utils import strict_json
from lftransfer.sim.verify import (IDENTICAL, NO_CROSS, NO_LIGHT, GroundTruth, evaluate, gt_noise_verdict)

H, W = 12, 16


def _result(real, synthetic, alpha):
    view = SimpleNamespace(rgb=synthetic, alpha=alpha)
    return SimpleNamespace(real_view=real, real_view_direct=real, synthetic_view=view,
                           bounces=[SimpleNamespace(synthetic_view=view)])


def _gt(union, real, synthetic, alpha_real, alpha_synthetic):
    return GroundTruth(union=np.stack([union, union]), real=np.stack([real, real]),
                       synthetic=np.stack([synthetic, synthetic]), alpha_real=alpha_real,
                       alpha_synthetic=alpha_synthetic)


def _strict(metrics: dict) -> dict:
    text = json.dumps(strict_json(metrics), allow_nan=False)
    return json.loads(text)


def test_01_black_scene_every_metric_is_null_with_a_reason():
    zero, ones = np.zeros((H, W, 3), np.float32), np.ones((H, W), np.float32)
    m = evaluate(_result(zero, zero, ones), _gt(zero, zero, zero, ones, ones))
    for key in ("psnr_db", "psnr_db_direct_only", "gt_noise_psnr_db", "cross_transfer_rel_error",
                "cross_gt_noise_rel", "cross_term_rel_size"):
        assert m[key] is None and m["undefined"][key], key
    assert m["undefined"]["psnr_db"] == NO_LIGHT and m["undefined"]["cross_transfer_rel_error"] == NO_CROSS
    assert _strict(m)["psnr_db"] is None


def test_02_no_cross_term_synthetic_objects_only():
    rng = np.random.default_rng(0)
    syn = rng.random((H, W, 3)).astype(np.float32)
    zero = np.zeros((H, W, 3), np.float32)
    alpha = np.ones((H, W), np.float32)
    noisy = syn + 0.01
    m = evaluate(_result(zero, noisy, alpha), _gt(syn, zero, syn, np.zeros((H, W), np.float32), alpha))
    assert m["psnr_db"] is not None and np.isfinite(m["psnr_db"])
    assert m["cross_transfer_rel_error"] is None and m["undefined"]["cross_transfer_rel_error"] == NO_CROSS
    assert m["undefined"]["gt_noise_psnr_db"] == IDENTICAL       # two identical ground truths
    _strict(m)


def test_03_noise_verdict_names_the_samples_that_would_resolve_it():
    verdict = gt_noise_verdict({"cross_gt_noise_rel": 0.33, "cross_transfer_rel_error": 0.26}, 128)
    assert verdict is not None and verdict.spp_needed == 4096      # 128 * (0.33 / (0.25 * 0.26))^2 = 3299 -> 4096
    assert "--gt-spp 4096" in verdict.message() and "0.33" in verdict.message()
    assert gt_noise_verdict({"cross_gt_noise_rel": 0.1, "cross_transfer_rel_error": 0.26}, 128) is None
    assert gt_noise_verdict({"cross_gt_noise_rel": None, "cross_transfer_rel_error": 0.26}, 128) is None
    big = gt_noise_verdict({"cross_gt_noise_rel": 0.2, "cross_transfer_rel_error": 0.39}, 64)
    assert big is not None and big.spp_needed >= 128                # always more than the run had
