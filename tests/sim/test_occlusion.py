"""The ground truth where a real object hides a synthetic one, and the metrics of both composites there
(lftransfer.sim.ground_truth.GroundTruth, lftransfer.sim.metrics.occlusion_metrics).

A 12 x 16 view: a synthetic square 1 m away (columns 4-11, rows 3-8), a real post 0.5 m away in front of it
(columns 8-9, every row), a real block beside it (columns 0-1); each lights the other (a cross term on both).

What each test shows:
- test_01: the ground truth's "both objects, no light between them" puts the post in front of the square where it
  is nearer (R + (1 - a_R) S), the square over the real view elsewhere; without depths it is the over operator;
  a camera in the array's plane (the paper's scenes) renders no depths at all.
- test_02: a transfer whose only error is 10 % of the cross term: composited by the true depths it scores as well
  on the hidden pixels as on the others; the over operator, which draws the square over the post, is at least
  6 dB worse there (the negative control the target needs), and its cross-transfer error is larger.
- test_03: the reverse (the square nearer than the post): the pixels where a synthetic object hides a real one are
  counted apart, both composites draw the square there and score alike; negative control: a real depth measured
  nearer than the square puts the post in front and loses more than 6 dB there.
- test_04: the built-in scene ``occlusion_reverse`` (a camera behind the array's plane, beside it): its ground truth
  shows a synthetic object in front of a real one and never the opposite; ``occlusion`` (a camera on the real side)
  shows the opposite only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from lftransfer.composite import composite
from lftransfer.real_depth import ViewDepth
from lftransfer.render.base import ViewImage
from lftransfer.scenes import builtin_scene, load_scene
from lftransfer.sim.ground_truth import GroundTruth, views_overlap
from lftransfer.sim.metrics import occlusion_metrics
from lftransfer.transfer.bounce import composite_view

H, W = 12, 16


def _layers():
    a_syn = np.zeros((H, W), np.float32)
    a_syn[3:9, 4:12] = 1
    a_real = np.zeros((H, W), np.float32)
    a_real[:, 8:10] = 1
    a_real[:, 0:2] = 1
    d_syn = np.where(a_syn > 0, 1.0, np.inf).astype(np.float32)
    d_real = np.where(a_real > 0, 0.5, np.inf).astype(np.float32)
    syn = a_syn[..., None] * np.array([0.1, 0.5, 0.1], np.float32)
    real = a_real[..., None] * np.array([0.6, 0.6, 0.6], np.float32)
    cross_syn = a_syn[..., None] * np.float32(0.05)          # light the square gets from the real objects
    cross_real = a_real[..., None] * np.float32(0.03)        # and the real objects from it
    return a_syn, a_real, d_syn, d_real, syn, real, cross_syn, cross_real


def _truth(depths: bool = True) -> GroundTruth:
    a_syn, a_real, d_syn, d_real, syn, real, cross_syn, cross_real = _layers()
    front = (a_real > 0) & (a_syn > 0)
    union = np.where(front[..., None], real + cross_real, composite(syn + cross_syn, a_syn, real + cross_real))
    seeds = np.stack([union, union + np.float32(1e-4)])
    return GroundTruth(union=seeds, real=np.stack([real, real]), synthetic=np.stack([syn, syn]), alpha_real=a_real,
                       alpha_synthetic=a_syn, depth_real=d_real if depths else None,
                       depth_synthetic=d_syn if depths else None)


@dataclass
class _Result:
    """What occlusion_metrics reads of a transfer result, composited as TransferResult composites."""

    real_view: np.ndarray
    real_view_direct: np.ndarray
    synthetic_view: ViewImage
    synthetic_direct: np.ndarray
    view_depth: ViewDepth | None

    def composite(self):
        return composite_view(self.synthetic_view, self.real_view, self.view_depth)

    def composite_direct(self):
        s = self.synthetic_view
        return composite_view(ViewImage(self.synthetic_direct, s.alpha, s.depth), self.real_view_direct,
                              self.view_depth)


def test_01_the_truth_without_exchange_keeps_the_nearer_surface():
    gt = _truth()
    a_syn, a_real, _, _, syn, real, _, _ = _layers()
    alone = gt.composite_alone(0)
    assert np.allclose(alone[5, 8], real[5, 8])                  # the post hides the square
    assert np.allclose(alone[5, 5], syn[5, 5])                   # the square, no real object behind it
    assert np.allclose(alone[0, 0], real[0, 0]) and np.allclose(alone[5, 13], 0)
    assert gt.real_in_front.sum() == 6 * 2 and gt.synthetic_seen[5, 8] == 0 and gt.synthetic_seen[5, 5] == 1
    over = _truth(depths=False)
    assert not over.real_in_front.any()
    assert np.allclose(over.composite_alone(0), composite(syn, a_syn, real))
    assert np.allclose(over.composite_alone(0)[5, 8], syn[5, 8])  # without depths: the over operator
    assert not views_overlap(load_scene(builtin_scene("fig4")))
    assert views_overlap(load_scene(builtin_scene("occlusion")))
    assert views_overlap(load_scene(builtin_scene("occlusion_reverse")))


def test_02_the_depth_composite_scores_the_hidden_pixels_as_the_rest():
    gt = _truth()
    a_syn, a_real, d_syn, d_real, syn, real, cross_syn, cross_real = _layers()
    depth = ViewDepth(np.where(np.isfinite(d_real), d_real, np.nan).astype(np.float32),
                      np.where(np.isfinite(d_real), 0.001, np.nan).astype(np.float32), "test")
    result = _Result(real_view=real + 0.9 * cross_real, real_view_direct=real,
                     synthetic_view=ViewImage(syn + 0.9 * cross_syn, a_syn, d_syn), synthetic_direct=syn,
                     view_depth=depth)
    m = occlusion_metrics(result, gt, target_width=W)
    assert m["hidden_pixels"] == 12
    d, o = m["depth"], m["over"]
    assert d["psnr_hidden_db"] >= d["psnr_objects_unhidden_db"] - 1.0
    assert m["depth_gain_hidden_db"] >= 6.0 and d["psnr_hidden_db"] - o["psnr_hidden_db"] >= 6.0
    assert d["psnr_objects_db"] > o["psnr_objects_db"]
    assert d["cross_transfer_rel_error"] < o["cross_transfer_rel_error"]
    assert abs(d["cross_transfer_rel_error"] - 0.1) < 0.01          # what the transfer got wrong, no more
    assert occlusion_metrics(result, _truth(depths=False), target_width=W) is None


def test_03_a_synthetic_object_in_front_of_a_real_one():
    a_syn, a_real, d_syn, d_real, syn, real, cross_syn, cross_real = _layers()
    d_syn = np.where(a_syn > 0, 0.3, np.inf).astype(np.float32)             # now nearer than the post
    front = (a_real > 0) & (a_syn > 0)
    union = composite(syn + cross_syn, a_syn, real + cross_real)
    gt = GroundTruth(union=np.stack([union, union + np.float32(1e-4)]), real=np.stack([real, real]),
                     synthetic=np.stack([syn, syn]), alpha_real=a_real, alpha_synthetic=a_syn, depth_real=d_real,
                     depth_synthetic=d_syn)
    assert not gt.real_in_front.any() and gt.synthetic_in_front.sum() == front.sum() == 12

    def run(real_depth):
        depth = ViewDepth(np.where(np.isfinite(real_depth), real_depth, np.nan).astype(np.float32),
                          np.where(np.isfinite(real_depth), 0.001, np.nan).astype(np.float32), "test")
        return _Result(real_view=real + 0.9 * cross_real, real_view_direct=real,
                       synthetic_view=ViewImage(syn + 0.9 * cross_syn, a_syn, d_syn), synthetic_direct=syn,
                       view_depth=depth)

    m = occlusion_metrics(run(d_real), gt, target_width=W)
    assert m["hidden_pixels"] == 0 and m["synthetic_front_pixels"] == 12
    assert m["depth"]["psnr_hidden_db"] is None and "depth_gain_hidden_db" not in m
    assert m["depth"]["psnr_synthetic_front_db"] == pytest.approx(m["over"]["psnr_synthetic_front_db"])
    wrong = occlusion_metrics(run(np.where(np.isfinite(d_real), 0.1, np.inf)), gt, target_width=W)
    assert wrong["depth"]["psnr_synthetic_front_db"] < m["depth"]["psnr_synthetic_front_db"] - 6.0


def test_04_which_side_can_be_in_front(variant):
    from lftransfer.scenes import with_overrides
    from lftransfer.sim.ground_truth import render_ground_truth

    for name, real_front in (("occlusion_reverse", False), ("occlusion", True)):
        scene = with_overrides(load_scene(builtin_scene(name)), view={"resolution": [64, 48]})
        gt = render_ground_truth(scene, spp=4, use_cache=False)
        assert gt.real_in_front.any() == real_front and gt.synthetic_in_front.any() != real_front, name
