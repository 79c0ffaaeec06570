"""A reference quiet enough to judge an error (docs/architecture.md, "A quiet reference").

A metric judged against a path-traced ground truth is only as good as that truth is quiet: the ground truth's own
noise on the cross term must be at most a third of the error it measures, or the error is mostly the reference's
noise. :func:`quiet_ground_truth` renders the ground truth in rounds until it is. After a first round over the
whole frame (the ordinary :func:`~lftransfer.sim.ground_truth.render_ground_truth`), the later rounds render only
the box of pixels the objects cover (the film's crop window: the cross term lives there, and the background's
samples would be wasted), with fresh seeds, and are averaged in weighted by their samples. The union and the objects
alone keep sharing each round's seeds (correlated sampling: their noise cancels in the cross term). Each round asks
for the samples that the noise's 1 / sqrt(spp) law says will meet the target, up to a budget.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass
from typing import Callable

import numpy as np

from lftransfer.sim.ground_truth import GroundTruth, render_ground_truth

__all__ = ["QUIET_RATIO", "MAX_ROUNDS", "Reference", "object_box", "quiet_ground_truth"]

QUIET_RATIO = 1.0 / 3.0        # the noise on the cross term at most this fraction of the error
MAX_ROUNDS = 4                 # rounds after the first
MAX_SPP = 65536                # samples per pixel per render, in all, at most
HEADROOM = 1.2                 # a round asks for this much more than the 1 / sqrt(spp) law's estimate


@dataclass(frozen=True)
class Reference:
    """How quiet the reference got (:func:`quiet_ground_truth`).

    Attributes:
        spp: samples per pixel of each render inside the objects' box, all rounds together.
        first_spp: the first round's, over the whole frame.
        rounds: rounds rendered (the first included).
        noise: the ground truth's noise on the cross term (its two seeds against each other, relative), reached.
        error: the error judged against it.
        ratio: noise / error (None where either is undefined).
        target: the ratio aimed at.
        met: whether ratio <= target.
        box: (x, y, width, height) of the pixels the later rounds rendered.
        samples: camera samples spent, all renders (6 per round: union, real, synthetic, two seeds each).
        seconds: wall time.
    """

    spp: int
    first_spp: int
    rounds: int
    noise: float | None
    error: float | None
    ratio: float | None
    target: float
    met: bool
    box: tuple[int, int, int, int]
    samples: int
    seconds: float

    def to_json(self) -> dict:
        d = asdict(self)
        d["box"] = list(self.box)
        return d


def object_box(gt: GroundTruth, multiple: int = 1) -> tuple[int, int, int, int]:
    """(x, y, width, height) of the pixels any object covers, grown to whole blocks of ``multiple`` pixels (the
    metrics' box downsampling), inside the frame."""
    h, w = gt.alpha_real.shape
    ys, xs = np.nonzero((gt.alpha_real > 0) | (gt.alpha_synthetic > 0))
    if len(xs) == 0:
        return 0, 0, w, h
    m = max(1, int(multiple))
    x0, y0 = (int(xs.min()) // m) * m, (int(ys.min()) // m) * m
    x1, y1 = min(w, -(-(int(xs.max()) + 1) // m) * m), min(h, -(-(int(ys.max()) + 1) // m) * m)
    return x0, y0, x1 - x0, y1 - y0


def _blend(gt: GroundTruth, n: int, more: GroundTruth, k: int, box: tuple[int, int, int, int]) -> GroundTruth:
    """``gt`` (``n`` spp per pixel in the box) and ``more`` (``k`` spp, the box only) averaged in the box."""
    x, y, w, h = box
    out = GroundTruth(union=gt.union.copy(), real=gt.real.copy(), synthetic=gt.synthetic.copy(),
                      alpha_real=gt.alpha_real.copy(), alpha_synthetic=gt.alpha_synthetic.copy())
    a, b = np.float32(n / (n + k)), np.float32(k / (n + k))
    for name in ("union", "real", "synthetic"):
        img = getattr(out, name)
        img[:, y:y + h, x:x + w] = a * img[:, y:y + h, x:x + w] + b * getattr(more, name)
    for name in ("alpha_real", "alpha_synthetic"):
        img = getattr(out, name)
        img[y:y + h, x:x + w] = a * img[y:y + h, x:x + w] + b * getattr(more, name)
    return out


def quiet_ground_truth(scene, judge: Callable[[GroundTruth], tuple[float | None, float | None]], *, spp: int,
                       target: float = QUIET_RATIO, max_spp: int = MAX_SPP, max_rounds: int = MAX_ROUNDS,
                       multiple: int = 1, seeds: tuple[int, int] = (1, 2), use_cache: bool = True,
                       progress: Callable[[str], None] | None = None,
                       warn: Callable[[str], None] | None = None) -> tuple[GroundTruth, Reference]:
    """The ground truth, rendered in rounds until its noise on the cross term is at most ``target`` times the error
    it judges (module docstring).

    Args:
        scene: the hidden world (``lftransfer.scenes.SceneConfig``).
        judge: ground truth -> (error, the ground truth's noise on the cross term), both relative to the cross term
            (``cross_transfer_error``'s ``error`` and ``gt_noise``); None where undefined.
        spp: the first round's samples per pixel (the whole frame).
        target: the noise / error ratio aimed at.
        max_spp: samples per pixel in the objects' box, in all, at most.
        max_rounds: rounds after the first, at most.
        multiple: the box is grown to whole blocks of this many pixels (the metrics' downsampling factor).
        seeds: the first round's two seeds; round r uses seeds + 7919 r.
        use_cache: read and write each round's renders in the ground-truth cache.
        progress: called once per round.
        warn: called with one line when a cache entry is bad.

    Returns:
        (the ground truth, :class:`Reference`). Where the target is not met within the budget, ``met`` says so.
    """
    t0 = time.perf_counter()
    say = progress or (lambda _msg: None)
    w, h = scene.view.resolution
    say(f"ground truth: {spp} samples per pixel, the whole frame")
    gt = render_ground_truth(scene, spp=spp, seeds=seeds, use_cache=use_cache, warn=warn)
    box = object_box(gt, multiple)
    total, rounds, samples = spp, 1, 6 * spp * w * h
    error, noise = judge(gt)
    while rounds <= max_rounds and error and noise is not None and noise > target * error and total < max_spp:
        need = total * (noise / (target * error)) ** 2 * HEADROOM
        more = int(min(max_spp - total, max(spp, math.ceil(need - total))))
        say(f"ground truth: noise {noise:.3g} of the error {error:.3g}; {more} more samples per pixel in the "
            f"objects' box")
        r_seeds = (seeds[0] + 7919 * rounds, seeds[1] + 7919 * rounds)
        extra = render_ground_truth(scene, spp=more, seeds=r_seeds, use_cache=use_cache, warn=warn, crop=box)
        gt = _blend(gt, total, extra, more, box)
        total += more
        rounds += 1
        samples += 6 * more * box[2] * box[3]
        error, noise = judge(gt)
    ratio = noise / error if error and noise is not None else None
    return gt, Reference(spp=total, first_spp=spp, rounds=rounds, noise=noise, error=error, ratio=ratio,
                         target=target, met=ratio is not None and ratio <= target, box=box, samples=samples,
                         seconds=time.perf_counter() - t0)
