"""A reference quiet enough to judge an error (docs/architecture.md, "A quiet reference").

A metric judged against a path-traced ground truth is only as good as that truth is quiet: the ground truth's own
noise on the cross term must be at most a third of the error it measures, or the error is mostly the reference's
noise. :func:`quiet_ground_truth` renders the ground truth in rounds until it is. After a first round over the
whole frame (the ordinary :func:`~lftransfer.sim.ground_truth.render_ground_truth`), the later rounds render only
the box of pixels the objects cover (the film's crop window: the cross term lives there, and the background's
samples would be wasted), with fresh seeds, and are averaged in weighted by their samples. The union and the objects
alone keep sharing each round's seeds (correlated sampling: their noise cancels in the cross term). Each round asks
for the samples that the noise's 1 / sqrt(spp) law says will meet the target, up to a budget, as renders of a power
of two samples each (Mitsuba repeats a render bit for bit only then).

A later round may be split into ``parts`` renders of its samples with seeds of their own, averaged in one after
another in their order: each part is a job (:data:`Job`) that any process can render (:func:`render_jobs` here,
or the workers of a Ray cluster, ``lftransfer.runs.reference_pool``), and the result depends on the number of parts
only, never on where or in which order they ran.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, replace
from typing import Callable

import numpy as np

from lftransfer.sim.ground_truth import GroundTruth, render_ground_truth

__all__ = ["QUIET_RATIO", "MAX_ROUNDS", "Job", "Reference", "cross_term_judge", "object_box", "quiet_ground_truth",
           "render_jobs"]

QUIET_RATIO = 1.0 / 3.0        # the noise on the cross term at most this fraction of the error
MAX_ROUNDS = 4                 # rounds after the first
MAX_SPP = 65536                # samples per pixel per render, in all, at most
HEADROOM = 1.2                 # a round asks for this much more than the 1 / sqrt(spp) law's estimate
PART_SEED_STEP = 104729        # part j of a round adds j times this to the round's seeds
UNTIMED_GROWTH = 32            # with a budget but no rate yet (renders too quick to time, or read from the cache), a
                               # round adds at most this many times the samples so far

Job = tuple[int, tuple[int, int], "tuple[int, int, int, int] | None"]
"""One render of a quiet reference: (samples per pixel, the two seeds, the crop box or None: the whole frame)."""


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
        parts: renders each later round was split into (the workers it was spread over).
        budget_s: the seconds the later rounds were given (None: no limit).
        stopped: why the rounds stopped: "met" (the target), "budget" (the next round would not fit the time
            left), "samples" (``MAX_SPP``), "rounds" (``MAX_ROUNDS``) or "undefined" (no error to judge).
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
    parts: int = 1
    budget_s: float | None = None
    stopped: str = "met"

    def to_json(self) -> dict:
        d = asdict(self)
        d["box"] = list(self.box)
        return d


def cross_term_judge(composite_n: np.ndarray, composite_0: np.ndarray
                     ) -> Callable[[GroundTruth], tuple[float | None, float | None]]:
    """The ``judge`` of :func:`quiet_ground_truth` for a frame: ground truth -> (the cross-transfer error of the
    frame ``composite_n`` against the frame without exchange ``composite_0``, the ground truth's noise on it)
    (:func:`~lftransfer.sim.metrics.cross_transfer_error`)."""
    from lftransfer.sim.metrics import cross_transfer_error

    def judge(gt: GroundTruth) -> tuple[float | None, float | None]:
        check = cross_transfer_error(composite_n, composite_0, gt)
        return check.error, check.gt_noise

    return judge


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
    out = replace(gt, union=gt.union.copy(), real=gt.real.copy(), synthetic=gt.synthetic.copy(),
                  alpha_real=gt.alpha_real.copy(), alpha_synthetic=gt.alpha_synthetic.copy())
    a, b = np.float32(n / (n + k)), np.float32(k / (n + k))
    for name in ("union", "real", "synthetic"):
        img = getattr(out, name)
        img[:, y:y + h, x:x + w] = a * img[:, y:y + h, x:x + w] + b * getattr(more, name)
    for name in ("alpha_real", "alpha_synthetic"):
        img = getattr(out, name)
        img[y:y + h, x:x + w] = a * img[y:y + h, x:x + w] + b * getattr(more, name)
    return out


def render_jobs(scene, jobs: list[Job], *, use_cache: bool = True,
                warn: Callable[[str], None] | None = None) -> list[GroundTruth]:
    """Each job's ground truth of ``scene`` (:func:`~lftransfer.sim.ground_truth.render_ground_truth`), one after
    another in this process, in the jobs' order."""
    return [render_ground_truth(scene, spp=n, seeds=seeds, crop=crop, use_cache=use_cache, warn=warn)
            for n, seeds, crop in jobs]


def _share(need: float, parts: int, room: int) -> int:
    """Samples per pixel of each of a round's ``parts`` renders: a power of two (Mitsuba 3.9 renders the same
    samples bit for bit only then; at 192, 320 or 1000 samples two renders with the same seed differed by up to
    1.4e-6), the smallest that brings ``need`` samples in all, or the largest that fits ``room``."""
    k = 1 << max(0, math.ceil(math.log2(max(1.0, need / parts))))
    while k > 1 and k * parts > room:
        k //= 2
    return k


def _add_round(scene, gt: GroundTruth, total: int, k: int, parts: int, seeds: tuple[int, int], index: int,
               box: tuple[int, int, int, int], render) -> tuple[GroundTruth, int]:
    """Round ``index``'s ``parts`` renders of ``k`` samples per pixel in ``box`` (seeds of their own) averaged into
    ``gt``, which had ``total``: (the ground truth, its samples per pixel in the box)."""
    jobs = [(k, (seeds[0] + 7919 * index + PART_SEED_STEP * j, seeds[1] + 7919 * index + PART_SEED_STEP * j), box)
            for j in range(parts)]
    for extra in render(scene, jobs):
        gt = _blend(gt, total, extra, k, box)
        total += k
    return gt, total


def _next_round(total: int, spp: int, excess: float, parts: int, room: int, seconds_left: float | None,
                per_spp: float | None) -> tuple[int, str | None]:
    """Samples per part of a quiet reference's next round, or (0, why none is rendered).

    Args:
        total: samples per pixel so far in the box; ``spp`` the first round's.
        excess: the noise over what the target allows (> 1).
        parts: renders the round is split into.
        room: samples per pixel left under ``MAX_SPP``.
        seconds_left: of the budget (None: no budget).
        per_spp: seconds one more sample per pixel in the box takes (None: not timed yet).
    """
    need = total * excess ** 2 * HEADROOM - total
    if seconds_left is not None:      # fitted to the time left; untimed, at most UNTIMED_GROWTH times the samples
        if seconds_left <= 0:
            return 0, "budget"
        room = min(room, int(seconds_left / per_spp) if per_spp is not None else UNTIMED_GROWTH * total)
    if room < parts:
        return 0, "budget" if seconds_left is not None else "samples"
    k = _share(max(spp, need), parts, room)
    if seconds_left is not None and room < need and k * parts < total / 4:   # too little to change the noise
        return 0, "budget"
    return k, None


def quiet_ground_truth(scene, judge: Callable[[GroundTruth], tuple[float | None, float | None]], *, spp: int,
                       target: float = QUIET_RATIO, max_spp: int = MAX_SPP, max_rounds: int = MAX_ROUNDS,
                       multiple: int = 1, seeds: tuple[int, int] = (1, 2), use_cache: bool = True,
                       parts: int = 1, render: Callable[[object, list[Job]], list[GroundTruth]] | None = None,
                       progress: Callable[[str], None] | None = None,
                       warn: Callable[[str], None] | None = None,
                       budget_s: float | None = None) -> tuple[GroundTruth, Reference]:
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
        parts: renders each later round is split into (part j adds j * 104729 to the round's seeds); the first
            round is one render (the ordinary ground truth, shared with the cache's).
        render: (scene, jobs) -> their ground truths in the jobs' order, e.g. on a cluster's workers (None:
            :func:`render_jobs` in this process).
        progress: called once per round.
        warn: called with one line when a cache entry is bad.
        budget_s: seconds the later rounds may take, all together (None: no limit). A round's samples are cut to
            what the rate of the renders so far says fits the time left, and none starts that would buy too little
            to change the noise (a quarter of the samples so far); renders too quick to time (or read from the
            cache) give no rate, and a round then adds at most :data:`UNTIMED_GROWTH` times the samples so far.

    Returns:
        (the ground truth, :class:`Reference`). Where the target is not met within the budget, ``met`` says so.
    """
    t0 = time.perf_counter()
    say = progress or (lambda _msg: None)
    w, h = scene.view.resolution
    if render is None:
        def render(sc, jobs):
            return render_jobs(sc, jobs, use_cache=use_cache, warn=warn)
    parts = max(1, int(parts))
    say(f"ground truth: {spp} samples per pixel, the whole frame")
    started = time.perf_counter()
    gt = render(scene, [(spp, seeds, None)])[0]
    box = object_box(gt, multiple)
    first_s = time.perf_counter() - started
    # seconds per sample and pixel (None until a render took long enough to time: a cached one takes none)
    rate = first_s / (spp * w * h) if first_s > 0.5 else None
    later_s, total, rounds, samples = 0.0, spp, 1, 6 * spp * w * h
    error, noise = judge(gt)
    stopped = "met"
    while error and noise is not None and noise > target * error:
        if rounds > max_rounds or total >= max_spp:
            stopped = "rounds" if rounds > max_rounds else "samples"
            break
        k, why = _next_round(total, spp, noise / (target * error), parts, max_spp - total,
                             None if budget_s is None else budget_s - later_s,
                             None if rate is None else rate * box[2] * box[3])
        if why is not None:
            stopped = why
            break
        more = k * parts
        say(f"ground truth: noise {noise:.3g} of the error {error:.3g}; {more} more samples per pixel in the "
            f"objects' box" + (f", {parts} parts" if parts > 1 else ""))
        started = time.perf_counter()
        gt, total = _add_round(scene, gt, total, k, parts, seeds, rounds, box, render)
        took = time.perf_counter() - started
        later_s += took
        if took > 0.5:
            rate = took / (more * box[2] * box[3])
        rounds += 1
        samples += 6 * more * box[2] * box[3]
        error, noise = judge(gt)
    if not (error and noise is not None):
        stopped = "undefined"
    ratio = noise / error if error and noise is not None else None
    return gt, Reference(spp=total, first_spp=spp, rounds=rounds, noise=noise, error=error, ratio=ratio,
                         target=target, met=ratio is not None and ratio <= target, box=box, samples=samples,
                         seconds=time.perf_counter() - t0, parts=parts, budget_s=budget_s, stopped=stopped)
