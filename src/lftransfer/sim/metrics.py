"""Metrics of a run against its ground truth: PSNR over the image and over the objects, the cross-transfer error
(what the objects add to each other's appearance), the ground truth's own noise on it, and the negative control.
They read the ground truth only (:class:`lftransfer.sim.ground_truth.GroundTruth`), never the hidden rig. A metric
that a scene leaves undefined (no light, no cross term) is None, with the reason in ``undefined``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields, replace

import numpy as np

from lftransfer.sim.ground_truth import GroundTruth, single_seed

__all__ = ["CrossCheck", "CrossSide", "Evaluation", "IDENTICAL", "NO_CROSS", "NO_LIGHT", "NO_PIXELS",
           "NegativeControl", "NoiseVerdict", "composites", "occlusion_metrics", "cross_by_side", "cross_term_truth",
           "cross_transfer_error", "downsample", "evaluate", "gt_noise_verdict", "metric_factor", "negative_control",
           "object_mask", "psnr"]

def downsample(image: np.ndarray, factor: int) -> np.ndarray:
    """Box-downsample the first two axes by an integer factor (cropping the remainder)."""
    if factor <= 1:
        return np.asarray(image, np.float64)
    h, w = image.shape[0] // factor * factor, image.shape[1] // factor * factor
    x = np.asarray(image[:h, :w], np.float64)
    return x.reshape(h // factor, factor, w // factor, factor, *x.shape[2:]).mean(axis=(1, 3))


def psnr(image: np.ndarray, reference: np.ndarray, peak: float | None = None,
         mask: np.ndarray | None = None) -> float:
    """Peak signal-to-noise ratio in dB; ``peak`` defaults to the reference's maximum.

    Args:
        image, reference: (H, W, 3) linear radiance.
        peak: the peak value (radiance); None: the reference's maximum.
        mask: (H, W) bool, the pixels whose squared errors are averaged; None: every pixel.

    Returns:
        dB; ``inf`` for identical images, ``nan`` for a peak of 0 or an empty mask (all undefined:
        :func:`evaluate` reports them as None with a reason).
    """
    peak = float(np.max(reference)) if peak is None else peak
    err2 = (np.asarray(image, np.float64) - reference) ** 2
    if mask is not None:
        err2 = err2[np.asarray(mask, bool)]
    if not peak > 0 or err2.size == 0:
        return float("nan")
    mse = float(np.mean(err2))
    return float("inf") if mse == 0 else 10.0 * math.log10(peak * peak / mse)


def metric_factor(width: int, target_width: int = 256) -> int:
    """Integer box-downsampling factor that brings ``width`` to about ``target_width``."""
    return max(1, int(round(width / target_width)))


def object_mask(gt: GroundTruth, factor: int) -> np.ndarray:
    """The pixels the objects cover, at the metrics' resolution: (H // factor, W // factor) bool, True where any
    real or synthetic object covers part of the pixel's ``factor`` x ``factor`` block.

    The one mask of every metric "over the pixels the objects cover" (the cross-transfer error and its noise,
    ``psnr_objects_db``).
    """
    return (downsample(gt.alpha_real, factor) > 0) | (downsample(gt.alpha_synthetic, factor) > 0)


NO_LIGHT = "the ground truth is black: no light reaches anything the view camera sees (light intensity 0, or " \
           "the light lights nothing in view)"
NO_CROSS = "the ground truth has no cross term: the real and synthetic objects add nothing to each other's " \
           "appearance (one side has no objects, or no light reaches them)"
NO_PIXELS = "no pixel of the view shows an object"
IDENTICAL = "the images are identical (PSNR is infinite)"


def cross_term_truth(gt: GroundTruth, factor: int) -> list[np.ndarray]:
    """The ground truth's cross term of each seed, C = union - composite(real alone, synthetic alone): what the
    objects add to each other's appearance; two (h, w, 3) images box-downsampled by ``factor``."""
    return [downsample(gt.union[i] - gt.composite_alone(i), factor)
            for i in range(2)]


def cross_term_image(gt: GroundTruth) -> np.ndarray:
    """(H, W, 3) the ground truth's cross term at full resolution, its two seeds' mean (:func:`cross_term_truth`):
    what ``cross_term.png`` shows beside the transfer's."""
    return 0.5 * sum(cross_term_truth(gt, 1))


@dataclass(frozen=True)
class CrossCheck:
    """The cross-transfer error of a composite and the ground truth's own noise on it.

    Attributes:
        error: ||C_transfer - C_truth|| / ||C_truth|| over the objects' pixels (None without a cross term).
        gt_noise: ||C_truth,1 - C_truth,2|| / ||C_truth||: the two ground-truth seeds' cross terms against each
            other; an error not well above it is the ground truth's noise, not the transfer's.
        by_side: the same split into the synthetic objects' pixels and the real ones' (:func:`cross_by_side`),
            or None without a cross term.
        truth_norm: ||C_truth|| over the objects' pixels (0.0 without a cross term, None without such pixels).
    """

    error: float | None
    gt_noise: float | None
    by_side: dict | None = None
    truth_norm: float | None = None


def cross_transfer_error(composite_n: np.ndarray, composite_0: np.ndarray, gt: GroundTruth, *,
                         target_width: int = 256) -> CrossCheck:
    """The cross-transfer error of any composite (:func:`evaluate`'s ``cross_transfer_rel_error`` and
    ``cross_gt_noise_rel``).

    Args:
        composite_n: (H, W, 3) the composite after the exchange (a converged result or a live frame).
        composite_0: (H, W, 3) the composite without any exchange (the projector black, the synthetic objects
            lit by the virtual point light and emitters only).
        gt: the ground truth at the same view resolution.
        target_width: the metrics' width.

    Returns:
        :class:`CrossCheck` over the objects' pixels.
    """
    f = metric_factor(composite_n.shape[1], target_width)
    pair = cross_term_truth(gt, f)
    c_gt = 0.5 * (pair[0] + pair[1])
    mask = object_mask(gt, f)
    if not mask.any():
        return CrossCheck(None, None)
    norm = lambda x: float(np.sqrt(np.sum(x[mask] ** 2)))  # noqa: E731
    c_norm = norm(c_gt)
    if not c_norm > 0:
        return CrossCheck(None, None, truth_norm=c_norm)
    c_lft = downsample(composite_n - composite_0, f)
    return CrossCheck(norm(c_lft - c_gt) / c_norm, norm(pair[0] - pair[1]) / c_norm,
                      cross_by_side(c_lft, pair, mask, downsample(gt.synthetic_seen, f) > 0.5), c_norm)


@dataclass(frozen=True)
class Evaluation:
    """Metrics of a transfer result against the ground truth (:func:`evaluate`). A metric the scene leaves undefined
    (a black ground truth, no cross term, identical images) is None and ``undefined`` says why.

    Attributes:
        psnr_db, psnr_db_direct_only: PSNR of the composite (N bounces, direct light only), every pixel, dB.
        psnr_objects_db, psnr_objects_db_direct_only: the same over the pixels the objects cover
            (:func:`object_mask`; the peak stays the ground truth's maximum), dB.
        cross_transfer_rel_error: ||C_lft - C_gt|| / ||C_gt|| over the objects (docs/architecture.md, "Verification").
        gt_noise_psnr_db: PSNR of the ground truth's two seeds against each other, dB.
        cross_gt_noise_rel: the ground truth's own noise on the cross term, relative to it.
        cross_term_rel_size: ||C_gt|| / ||union||: how much of the image the exchange is.
        metric_resolution: (width, height) of the box-downsampled images the metrics are computed on.
        metric_pixels: pixels (at that resolution) the objects cover.
        undefined: metric -> why it is None.
        cross_by_side: the cross-transfer error split by where it shows (:func:`cross_by_side`): ``"real"``, the
            real objects lit by the synthetic ones through the projector; ``"synthetic"``, the synthetic objects
            lit by the captured light field. Empty where the cross term is undefined.
        psnr_by_side: ``psnr_objects_db`` split the same way (``"real"``, ``"synthetic"``; None where a side shows
            no pixel): what the synthetic objects' direct light changes shows on the ``"synthetic"`` pixels.
    """

    psnr_db: float | None
    psnr_db_direct_only: float | None
    psnr_objects_db: float | None
    psnr_objects_db_direct_only: float | None
    cross_transfer_rel_error: float | None
    gt_noise_psnr_db: float | None
    cross_gt_noise_rel: float | None
    cross_term_rel_size: float | None
    metric_resolution: tuple[int, int]
    metric_pixels: int
    undefined: dict[str, str]
    cross_by_side: dict[str, "CrossSide"] = field(default_factory=dict)
    psnr_by_side: dict[str, float | None] = field(default_factory=dict)

    def to_json(self) -> dict:
        """The metrics as JSON data (None for undefined values; ``metric_resolution`` a list)."""
        return {**{f.name: getattr(self, f.name) for f in fields(self)},
                "metric_resolution": list(self.metric_resolution), "undefined": dict(self.undefined),
                "cross_by_side": {side: asdict(v) for side, v in self.cross_by_side.items()}}


@dataclass(frozen=True)
class CrossSide:
    """The cross-transfer term over the pixels of one side's objects.

    Attributes:
        rel_error: ||C_lft - C_gt|| / ||C_gt|| over these pixels (None: no cross term there).
        energy_ratio: sum of C_lft / sum of C_gt: below 1, light of the exchange is missing on this side.
        rel_error_shape: the error left after the best single scale of C_lft: what the energy does not explain.
        gt_noise_rel: the two ground truths' cross terms against each other over ||C_gt||, here.
        pixels: pixels at the metrics' resolution.
    """

    rel_error: float | None
    energy_ratio: float | None
    rel_error_shape: float | None
    gt_noise_rel: float | None
    pixels: int


def cross_by_side(c_lft: np.ndarray, c_gt_pair: list[np.ndarray], covered: np.ndarray,
                  synthetic: np.ndarray) -> dict[str, CrossSide]:
    """The cross term's error split into the pixels where a synthetic object is seen (lit by the captured light
    field) and those where only real objects are (lit through the projector).

    Args:
        c_lft: (h, w, 3) the transfer's cross term at the metrics' resolution.
        c_gt_pair: the two ground truths' cross terms (:func:`cross_term_truth`), (h, w, 3) each.
        covered: (h, w) bool, the pixels the objects cover (:func:`object_mask`).
        synthetic: (h, w) bool, the pixels where a synthetic object is seen.

    Returns:
        ``{"real": CrossSide, "synthetic": CrossSide}``.
    """
    c_gt = 0.5 * (c_gt_pair[0] + c_gt_pair[1])
    out = {}
    for side, where in (("real", covered & ~synthetic), ("synthetic", covered & synthetic)):
        g, l_ = c_gt[where], c_lft[where]
        g2 = float(np.sum(g.astype(np.float64) ** 2))
        if not g2 > 0:
            out[side] = CrossSide(None, None, None, None, int(where.sum()))
            continue
        scale = float(np.sum(g * l_) / max(float(np.sum(l_.astype(np.float64) ** 2)), 1e-300))
        out[side] = CrossSide(
            rel_error=float(np.sqrt(np.sum((l_ - g) ** 2) / g2)),
            energy_ratio=float(np.sum(l_) / np.sum(g)) if np.sum(g) != 0 else None,
            rel_error_shape=float(np.sqrt(np.sum((scale * l_ - g) ** 2) / g2)),
            gt_noise_rel=float(np.sqrt(np.sum((c_gt_pair[0][where] - c_gt_pair[1][where]) ** 2) / g2)),
            pixels=int(where.sum()))
    return out


def composites(result) -> tuple[np.ndarray, np.ndarray]:
    """(the composite after the exchange, the composite without it) of a transfer result: what the cross term of
    :func:`cross_transfer_error` is the difference of, (H, W, 3) each."""
    return result.composite(), result.composite_direct()


def evaluate(result, gt: GroundTruth, *, target_width: int = 256) -> Evaluation:
    """Metrics of a transfer result against the ground truth (docs/architecture.md, "Verification").

    A metric that the scene leaves undefined (a black ground truth, no cross term, identical images) is None
    and ``undefined`` says why; every other value is a finite float.

    Args:
        result: ``lftransfer.transfer.TransferResult``.
        gt: :class:`GroundTruth` at the same view resolution.
        target_width: metrics are computed on images box-downsampled to about this width.

    Returns:
        :class:`Evaluation`.
    """
    f = metric_factor(result.real_view.shape[1], target_width)
    comp_n, comp_0 = composites(result)
    ds = lambda x: downsample(x, f)  # noqa: E731
    union = ds(gt.image)
    peak = float(union.max())
    cross = cross_transfer_error(comp_n, comp_0, gt, target_width=target_width)   # what the objects add to each other
    mask = object_mask(gt, f)
    seen = downsample(gt.synthetic_seen, f) > 0.5          # where a synthetic object is seen (as cross_by_side)
    u_norm = float(np.sqrt(np.sum(union[mask] ** 2)))
    undefined: dict[str, str] = {}

    def defined(key: str, value: float, reason: str) -> float | None:
        if math.isfinite(value):
            return float(value)
        undefined[key] = reason
        return None

    def psnr_of(key: str, image: np.ndarray, reference: np.ndarray, where: np.ndarray | None = None) -> float | None:
        reason = NO_LIGHT if not peak > 0 else NO_PIXELS if where is not None and not where.any() else IDENTICAL
        return defined(key, psnr(image, reference, peak, mask=where), reason)

    def ratio(key: str, value: float | None, reason: str) -> float | None:
        return defined(key, float("nan") if value is None else value, reason if mask.any() else NO_PIXELS)

    return Evaluation(
        psnr_db=psnr_of("psnr_db", ds(comp_n), union),
        psnr_db_direct_only=psnr_of("psnr_db_direct_only", ds(comp_0), union),
        psnr_objects_db=psnr_of("psnr_objects_db", ds(comp_n), union, mask),
        psnr_objects_db_direct_only=psnr_of("psnr_objects_db_direct_only", ds(comp_0), union, mask),
        cross_transfer_rel_error=ratio("cross_transfer_rel_error", cross.error, NO_CROSS),
        gt_noise_psnr_db=psnr_of("gt_noise_psnr_db", ds(gt.union[0]), ds(gt.union[1])),
        cross_gt_noise_rel=ratio("cross_gt_noise_rel", cross.gt_noise, NO_CROSS),
        cross_term_rel_size=ratio("cross_term_rel_size",
                                  cross.truth_norm / u_norm if cross.truth_norm is not None and u_norm > 0 else None,
                                  NO_LIGHT),
        metric_resolution=(int(union.shape[1]), int(union.shape[0])),
        metric_pixels=int(mask.sum()),
        undefined=undefined,
        cross_by_side=cross.by_side or {},
        psnr_by_side={side: psnr_of(f"psnr_by_side.{side}", ds(comp_n), union, mask & where)
                      for side, where in (("real", ~seen), ("synthetic", seen))},
    )


@dataclass(frozen=True)
class NoiseVerdict:
    """The ground truth's own noise on the cross term, set against the error it measures.

    Attributes:
        noise: ``cross_gt_noise_rel``, the difference of the two independent ground truths' cross terms over the
            cross term.
        error: ``cross_transfer_rel_error``.
        spp: the ground truth's samples per pixel.
        spp_needed: samples per pixel at which the noise would fall to a quarter of the error (it falls as
            1 / sqrt(spp)), rounded up to a power of two.
    """

    noise: float
    error: float
    spp: int
    spp_needed: int

    def message(self) -> str:
        """One line for the terminal and the report."""
        return (f"the ground truth's own noise on the cross term ({self.noise:.3g}) is more than half the "
                f"cross-transfer error it measures ({self.error:.3g}) at {self.spp} samples per pixel, so the error "
                f"is mostly noise; --gt-spp {self.spp_needed} would bring the noise to about a quarter of it")


def gt_noise_verdict(metrics: Evaluation, spp: int, *, threshold: float = 0.5,
                     target: float = 0.25) -> NoiseVerdict | None:
    """A :class:`NoiseVerdict` when ``cross_gt_noise_rel`` exceeds ``threshold`` x ``cross_transfer_rel_error``,
    else None (also when either is undefined).

    Args:
        metrics: from :func:`evaluate` (its ``cross_gt_noise_rel`` and ``cross_transfer_rel_error``).
        spp: the ground truth's samples per pixel.
        threshold: noise / error above which the error is not trusted.
        target: noise / error the suggested sample count reaches.
    """
    noise, error = metrics.cross_gt_noise_rel, metrics.cross_transfer_rel_error
    if noise is None or error is None or not noise > threshold * error:
        return None
    factor = (noise / (target * error)) ** 2 if error > 0 else float("inf")
    needed = spp * factor
    spp_needed = int(2 ** math.ceil(math.log2(needed))) if math.isfinite(needed) and needed >= 1 else 2 ** 20
    return NoiseVerdict(noise=float(noise), error=float(error), spp=int(spp), spp_needed=max(spp_needed, 2 * spp))


@dataclass(frozen=True)
class NegativeControl:
    """The same run with a rig model that knows less (the rig file's nominal values on a rig built otherwise),
    set against the run: a metric that cannot tell them apart is blind.

    Attributes:
        rig_model: what the control knew of the rig (e.g. "nominal (rig file)").
        psnr_objects_db: the control's PSNR over the pixels the objects cover, dB (None: undefined).
        psnr_db: the control's full-frame PSNR, dB (None: undefined).
        cross_transfer_rel_error: the control's cross-transfer error, a fraction of norm(C_gt) (None: undefined).
        psnr_objects_margin_db: the run's ``psnr_objects_db`` minus the control's, dB: > 0 when the run is better.
        cross_error_margin: the control's cross-transfer error minus the run's: > 0 when the run is better.
        psnr_objects_margin_db_per_gt, cross_error_margin_per_gt: the same two margins against each of the two
            independently seeded ground truths alone (None where undefined): how much the ground truth's own
            noise moves them.
        measurably_worse: the control scores worse than the run by both measures (higher cross-transfer error,
            lower ``psnr_objects_db``) against the ground truth and against each of its two seeds alone.
    """

    rig_model: str
    psnr_objects_db: float | None
    psnr_db: float | None
    cross_transfer_rel_error: float | None
    psnr_objects_margin_db: float | None
    cross_error_margin: float | None
    psnr_objects_margin_db_per_gt: tuple[float | None, float | None]
    cross_error_margin_per_gt: tuple[float | None, float | None]
    measurably_worse: bool

    def to_json(self) -> dict:
        """The report's ``negative_control`` entry (plain floats and lists, None for undefined values)."""
        return {"rig_model": self.rig_model, "psnr_objects_db": self.psnr_objects_db, "psnr_db": self.psnr_db,
                "cross_transfer_rel_error": self.cross_transfer_rel_error,
                "psnr_objects_margin_db": self.psnr_objects_margin_db, "cross_error_margin": self.cross_error_margin,
                "psnr_objects_margin_db_per_gt": list(self.psnr_objects_margin_db_per_gt),
                "cross_error_margin_per_gt": list(self.cross_error_margin_per_gt),
                "measurably_worse": self.measurably_worse}

    def message(self) -> str:
        """One line for the terminal and the report when the control is not measurably worse."""
        def fmt(values) -> str:
            return ", ".join("undefined" if v is None else f"{v:.3g}" for v in values)

        interfaces = self.rig_model.startswith("through")      # several interfaces' control: not a rig model
        what = self.rig_model if interfaces else f"{self.rig_model} rig model"
        tell = "the run through fewer interfaces from the run" if interfaces else "this rig model from the run's"
        return (f"the negative control ({what}) is not measurably worse than the run: "
                f"psnr_objects_db margin {fmt([self.psnr_objects_margin_db])} dB "
                f"({fmt(self.psnr_objects_margin_db_per_gt)} against each ground-truth seed), cross-error margin {fmt([self.cross_error_margin])} "
                f"({fmt(self.cross_error_margin_per_gt)}); the metrics cannot tell {tell}")


def _margins(run: Evaluation, control: Evaluation) -> tuple[float | None, float | None]:
    """(run's psnr_objects_db - control's, control's cross error - run's); None where either is undefined."""
    def diff(a: float | None, b: float | None) -> float | None:
        return None if a is None or b is None else float(a - b)

    return (diff(run.psnr_objects_db, control.psnr_objects_db),
            diff(control.cross_transfer_rel_error, run.cross_transfer_rel_error))


def negative_control(result, control, gt: GroundTruth, rig_model: str, *, target_width: int = 256) -> NegativeControl:
    """Set a run against its negative control, both evaluated (:func:`evaluate`) against the same ground truth
    and against each of its two seeds alone.

    Args:
        result: the run's ``TransferResult``.
        control: the control's ``TransferResult`` (same scene, same rig, a rig model that knows less).
        gt: the ground truth both are measured against.
        rig_model: what the control knew of the rig.
        target_width: as in :func:`evaluate`.
    """
    run_m, ctl_m = evaluate(result, gt, target_width=target_width), evaluate(control, gt, target_width=target_width)
    psnr_margin, cross_margin = _margins(run_m, ctl_m)
    per_gt = [_margins(evaluate(result, g, target_width=target_width), evaluate(control, g, target_width=target_width))
              for g in (single_seed(gt, 0), single_seed(gt, 1))]
    worse = all(m is not None and m > 0 for pair in [(psnr_margin, cross_margin), *per_gt] for m in pair)
    return NegativeControl(rig_model=rig_model, psnr_objects_db=ctl_m.psnr_objects_db, psnr_db=ctl_m.psnr_db,
                           cross_transfer_rel_error=ctl_m.cross_transfer_rel_error,
                           psnr_objects_margin_db=psnr_margin, cross_error_margin=cross_margin,
                           psnr_objects_margin_db_per_gt=(per_gt[0][0], per_gt[1][0]),
                           cross_error_margin_per_gt=(per_gt[0][1], per_gt[1][1]), measurably_worse=bool(worse))


def depth_errors(estimate, truth: np.ndarray) -> dict:
    """A real depth map in the view camera (:class:`lftransfer.real_depth.ViewDepth`) against the true one.

    Args:
        estimate: the measured depth (NaN: unknown) and its sigma.
        truth: (H, W) true distance to the real objects, metres (inf: none seen).

    Returns:
        ``error_mm_median`` and ``error_mm_p95`` (|estimate - truth| where both are known, mm), ``within_3_sigma``
        (the fraction of those within three of the estimate's sigmas), ``coverage`` (of the pixels that see a real
        object, the fraction with an estimate), ``false_fraction`` (of the pixels with an estimate, the fraction
        that see no real object) and ``pixels`` (both known); None where undefined.
    """
    real = np.isfinite(truth)
    known = np.isfinite(estimate.depth)
    both = real & known
    err = np.abs(estimate.depth[both].astype(np.float64) - truth[both])
    return {"error_mm_median": float(np.median(err) * 1000) if both.any() else None,
            "error_mm_p95": float(np.percentile(err, 95) * 1000) if both.any() else None,
            "within_3_sigma": float(np.mean(err <= 3 * estimate.sigma[both])) if both.any() else None,
            "coverage": float(both.sum() / real.sum()) if real.any() else None,
            "false_fraction": float((known & ~real).sum() / known.sum()) if known.any() else None,
            "pixels": int(both.sum())}


#: The true depth's standard deviation in ``occlusion_metrics``' ``true_depth`` composite, metres: as sure as the
#: synthetic render's own depth.
TRUE_DEPTH_SIGMA_M = 0.001


def occlusion_metrics(result, gt: GroundTruth, *, target_width: int = 256) -> dict | None:
    """How each composite fares where a real object hides a synthetic one, or the reverse (docs/architecture.md,
    "Occlusion").

    The same transfer is put together by the over operator (the paper's composite, which draws every synthetic
    object in front) and, where the run measured the real scene's depth in the view camera, by the depth-aware
    composite; each is scored against the ground truth.

    Args:
        result: ``lftransfer.transfer.TransferResult`` (its ``view_depth`` set by ``composite = "depth"``).
        gt: :class:`GroundTruth` with the true depths (``depth_real``, ``depth_synthetic``).
        target_width: the metrics' resolution (:func:`metric_factor`).

    Returns:
        None where neither side hides the other in the ground truth; else ``hidden_pixels`` (pixels at the metrics'
        resolution any part of which shows a real object in front of a synthetic one), ``synthetic_front_pixels``
        (the same for a synthetic object in front of a real one) and, for ``over`` and (where measured) ``depth``:
        ``psnr_hidden_db`` (over the hidden pixels; None where there are none), ``psnr_synthetic_front_db`` (over
        the others; None where none), ``psnr_objects_db``, ``psnr_objects_unhidden_db`` (over the objects' pixels
        where nothing is hidden) and ``cross_transfer_rel_error``; ``true_depth``, the same for the depth
        composite given the twin's true depth, where the truth rendered one (what an exact depth gives; not a bound:
        a pixel a real object only partly covers is all real with it); ``depth_gain_hidden_db``: depth minus over
        on the hidden pixels.
    """
    front, reverse = gt.real_in_front, gt.synthetic_in_front
    if not front.any() and not reverse.any():
        return None
    f = metric_factor(result.real_view.shape[1], target_width)
    hidden = downsample(front.astype(np.float32), f) > 0
    ahead = (downsample(reverse.astype(np.float32), f) > 0) & ~hidden
    union = downsample(gt.image, f)
    peak = float(union.max())
    unhidden = object_mask(gt, f) & ~hidden & ~ahead
    runs = {"over": replace(result, view_depth=None)}
    if result.view_depth is not None:
        runs["depth"] = result
        if gt.depth_real is not None:         # the same transfer composited with the twin's true depth
            from lftransfer.real_depth.lightfield import ViewDepth

            true = np.where(np.isfinite(gt.depth_real), gt.depth_real, np.nan).astype(np.float32)
            sigma = np.where(np.isfinite(true), TRUE_DEPTH_SIGMA_M, np.nan).astype(np.float32)
            runs["true_depth"] = replace(result, view_depth=ViewDepth(true, sigma, "truth"))
    out: dict = {"hidden_pixels": int(hidden.sum()), "synthetic_front_pixels": int(ahead.sum())}
    for name, run in runs.items():
        frame = downsample(run.composite(), f)
        m = evaluate(run, gt, target_width=target_width)
        out[name] = {"psnr_hidden_db": _finite(psnr(frame, union, peak, mask=hidden)) if hidden.any() else None,
                     "psnr_synthetic_front_db": _finite(psnr(frame, union, peak, mask=ahead)) if ahead.any() else None,
                     "psnr_objects_db": m.psnr_objects_db,
                     "psnr_objects_unhidden_db": _finite(psnr(frame, union, peak, mask=unhidden))
                     if unhidden.any() else None,
                     "cross_transfer_rel_error": m.cross_transfer_rel_error}
    if "depth" in out and out["depth"]["psnr_hidden_db"] is not None and out["over"]["psnr_hidden_db"] is not None:
        out["depth_gain_hidden_db"] = out["depth"]["psnr_hidden_db"] - out["over"]["psnr_hidden_db"]
    return out


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def probe_errors(probe, truth: np.ndarray, world_to_array: np.ndarray) -> dict:
    """A light probe's map against the true room (docs/architecture.md, "The light probe").

    Args:
        probe: ``lftransfer.real_depth.probe.ProbeMeasurement`` (its maps in the lens array's frame as the
            pipeline knows it).
        truth: (H, W, 3) the room's true radiance map, world frame (any size; read along the probe's directions as
            Mitsuba reads it).
        world_to_array: (4, 4) the frame the probe's maps are in, from the world.

    Returns:
        JSON: ``brightest_direction_error_deg`` (the measured map's brightest spot against the true map's, each
        :meth:`~lftransfer.real_depth.probe.EnvironmentMap.peak_direction`),
        ``power_ratio`` (measured / true radiance integrated over the measured directions, per channel, then
        their mean), ``texel_rel_error_median`` (the measured texels away from the brightest 1 %, where a texel's
        share of a sun's edge dominates), ``measured_share`` (of the sphere, by solid angle).
    """
    from lftransfer.real_depth.probe import EnvironmentMap
    from lftransfer.optics.geometry import env_directions
    from lftransfer.render.lights import EnvironmentLight

    h, w = probe.measured.valid.shape
    # the true room along each of the probe's directions, looked up as the renderers look it up
    room = EnvironmentLight(np.asarray(truth, np.float32), np.asarray(world_to_array, float)[:3, :3])
    d = env_directions(w, h).reshape(-1, 3).astype(np.float32)
    true = room.background(np.zeros_like(d), d).reshape(h, w, 3)
    valid = probe.measured.valid
    measured = EnvironmentMap(probe.measured.radiance, valid)
    reference = EnvironmentMap(true.astype(np.float32), valid)
    b_true = EnvironmentMap(true.astype(np.float32), np.ones_like(valid)).peak_direction()
    b_meas = measured.peak_direction()
    grey = true.sum(-1)
    quiet = valid & (grey < np.quantile(grey, 0.99))
    rel = np.abs(probe.measured.radiance[quiet] - true[quiet]).sum(-1) / np.maximum(grey[quiet], 1e-12)
    return {"brightest_direction_error_deg": float(np.degrees(np.arccos(np.clip(b_true @ b_meas, -1.0, 1.0)))),
            "power_ratio": float(np.mean(measured.power() / np.maximum(reference.power(), 1e-12))),
            "texel_rel_error_median": float(np.median(rel)) if rel.size else float("nan"),
            "measured_share": 1.0 - probe.filled_share}
