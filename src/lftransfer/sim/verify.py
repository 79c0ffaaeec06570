"""Verification against path-traced ground truth (DESIGN.md section 6). Only this module (and tests) may read
a simulated rig's hidden truth.

The ground truth is the union scene (real objects + synthetic objects + point light, no lens array) path traced
from the view camera with Mitsuba's ``path`` integrator; the real-alone and synthetic-alone scenes are rendered
with the same seeds so that their noise cancels in the cross-transfer term. Two independent seeds give the
ground truth's own noise. Renders are cached under a hash of everything they depend on, each entry with its
checksum (:mod:`lftransfer.sim.gt_cache`). A metric that a scene leaves undefined (no light, no cross term) is
None, with the reason in ``undefined``.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Callable

import numpy as np

from lftransfer.composite import composite
from lftransfer.optics.geometry import apply_homography, rotation_xy, rotation_z
from lftransfer.render.camera import sensor_dict
from lftransfer.render.shapes import scene_dict
from lftransfer.sim.gt_cache import CacheProblem, cache_dir, read_entry, write_entry

__all__ = ["CalibrationErrors", "CrossCheck", "CrossSide", "cross_by_side", "GroundTruth", "NegativeControl", "NoiseVerdict", "cache_dir", "calibration_errors",
           "cross_term_truth", "cross_transfer_error", "downsample", "Evaluation", "evaluate", "gt_noise_verdict", "metric_factor",
           "negative_control", "object_mask", "psnr", "render_ground_truth", "single_seed"]

GT_MAX_DEPTH = 12  # Mitsuba path depth (counts the segment to the emitter): far beyond what transfer keeps


@dataclass
class GroundTruth:
    """Ground-truth view images, each rendered with two independent seeds.

    Attributes:
        union: (2, H, W, 3) float32, all objects together.
        real: (2, H, W, 3) float32, real objects alone.
        synthetic: (2, H, W, 3) float32, synthetic objects alone.
        alpha_real, alpha_synthetic: (H, W) float32 coverage of each set of objects.
    """

    union: np.ndarray
    real: np.ndarray
    synthetic: np.ndarray
    alpha_real: np.ndarray
    alpha_synthetic: np.ndarray

    @property
    def image(self) -> np.ndarray:
        """(H, W, 3) the ground truth: the mean of the two union renders."""
        return self.union.mean(axis=0)


def _inputs_hash(scene, spp: int, seeds: tuple[int, ...]) -> str:
    """SHA-256 (hex) of everything the ground-truth renders depend on."""
    import mitsuba

    def objects(objs):
        out = []
        for o in objs:
            d = o.model_dump(mode="json")
            if getattr(o, "file", None):
                d["file_sha"] = hashlib.sha256(Path(o.file).read_bytes()).hexdigest()
            out.append(d)
        return out

    payload = {
        "real": objects(scene.real), "synthetic": objects(scene.synthetic),
        # one light hashes as the single table it was before several were possible (cached entries stay valid)
        "light": _lights_key(scene.lights), "view": scene.view.model_dump(mode="json"),
        "spp": spp, "seeds": list(seeds), "depth": GT_MAX_DEPTH, "mitsuba": mitsuba.__version__, "v": 1,
    }
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()


def _lights_key(lights) -> dict | list | None:
    dumps = [lt.model_dump(mode="json") for lt in lights]
    return None if not dumps else dumps[0] if len(dumps) == 1 else dumps


STACK_CHANNELS = 20     # union, real, synthetic x 2 seeds x RGB, then the real and synthetic alphas


def render_ground_truth(scene, *, spp: int = 256, seeds: tuple[int, int] = (1, 2), use_cache: bool = True,
                        progress: Callable[[str], None] | None = None,
                        warn: Callable[[str], None] | None = None) -> GroundTruth:
    """Path trace the union, real-alone and synthetic-alone scenes from the view camera.

    Args:
        scene: ``lftransfer.scenes.SceneConfig`` (its ``real`` objects are the hidden truth).
        spp: samples per pixel of each render.
        seeds: the two independent seeds.
        use_cache: read and write the cache (:mod:`lftransfer.sim.gt_cache`); an entry that fails its checks is
            rendered again and replaced.
        progress: called before each render.
        warn: called with one line when a cache entry is bad.

    Returns:
        GroundTruth.
    """
    from lftransfer.backend import mitsuba

    w, h = scene.view.resolution
    inputs = _inputs_hash(scene, spp, seeds)
    if use_cache:
        cached = read_entry(inputs, (h, w, STACK_CHANNELS))
        if isinstance(cached, np.ndarray):
            return _unpack(cached)
        if isinstance(cached, CacheProblem) and warn is not None:
            warn(cached.message())
    mi = mitsuba()
    view = scene.view
    light = {("point_light" if i == 0 else f"point_light_{i}"):
             {"type": "point", "position": list(map(float, lt.position)),
              "intensity": {"type": "rgb", "value": list(map(float, lt.intensity))}}
             for i, lt in enumerate(scene.lights)}
    extra = {"sensor": sensor_dict(view.origin, view.target, view.up, view.fov_deg, w, h, spp=spp),
             "integrator": {"type": "path", "max_depth": GT_MAX_DEPTH, "hide_emitters": False},
             **light}
    images: dict[str, list[np.ndarray]] = {}
    for name, objs in (("union", scene.real + scene.synthetic), ("real", scene.real), ("synthetic", scene.synthetic)):
        mscene = mi.load_dict(scene_dict(objs, extra=extra), parallel=False, optimize=False)
        images[name] = []
        for seed in seeds:
            if progress:
                progress(f"ground truth: {name}, seed {seed}")
            images[name].append(np.array(mi.render(mscene, spp=spp, seed=seed), dtype=np.float32))
    stack = np.concatenate([images[n][i][..., :3] for n in ("union", "real", "synthetic") for i in range(2)]
                           + [images["real"][0][..., 3:4], images["synthetic"][0][..., 3:4]], axis=-1)
    if use_cache:
        write_entry(inputs, stack)
    return _unpack(stack)


def _unpack(stack: np.ndarray) -> GroundTruth:
    parts = [stack[..., 3 * i:3 * i + 3] for i in range(6)]
    return GroundTruth(union=np.stack(parts[0:2]), real=np.stack(parts[2:4]), synthetic=np.stack(parts[4:6]),
                       alpha_real=stack[..., 18], alpha_synthetic=stack[..., 19])


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
    return [downsample(gt.union[i] - composite(gt.synthetic[i], gt.alpha_synthetic, gt.real[i]), factor)
            for i in range(2)]


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
                      cross_by_side(c_lft, pair, mask, downsample(gt.alpha_synthetic, f) > 0.5), c_norm)


@dataclass(frozen=True)
class Evaluation:
    """Metrics of a transfer result against the ground truth (:func:`evaluate`). A metric the scene leaves undefined
    (a black ground truth, no cross term, identical images) is None and ``undefined`` says why.

    Attributes:
        psnr_db, psnr_db_direct_only: PSNR of the composite (N bounces, direct light only), every pixel, dB.
        psnr_objects_db, psnr_objects_db_direct_only: the same over the pixels the objects cover
            (:func:`object_mask`; the peak stays the ground truth's maximum), dB.
        cross_transfer_rel_error: ||C_lft - C_gt|| / ||C_gt|| over the objects (DESIGN.md section 6).
        gt_noise_psnr_db: PSNR of the ground truth's two seeds against each other, dB.
        cross_gt_noise_rel: the ground truth's own noise on the cross term, relative to it.
        cross_term_rel_size: ||C_gt|| / ||union||: how much of the image the exchange is.
        metric_resolution: (width, height) of the box-downsampled images the metrics are computed on.
        metric_pixels: pixels (at that resolution) the objects cover.
        undefined: metric -> why it is None.
        cross_by_side: the cross-transfer error split by where it shows (:func:`cross_by_side`): ``"real"``, the
            real objects lit by the synthetic ones through the projector; ``"synthetic"``, the synthetic objects
            lit by the captured light field. Empty where the cross term is undefined.
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


def evaluate(result, gt: GroundTruth, *, target_width: int = 256) -> Evaluation:
    """Metrics of a transfer result against the ground truth (DESIGN.md section 6).

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
    alpha = result.synthetic_view.alpha
    comp_n = composite(result.synthetic_view.rgb, alpha, result.real_view)
    s0 = result.bounces[0].synthetic_view
    comp_0 = composite(s0.rgb, alpha, result.real_view_direct)
    ds = lambda x: downsample(x, f)  # noqa: E731
    union = ds(gt.image)
    peak = float(union.max())
    cross = cross_transfer_error(comp_n, comp_0, gt, target_width=target_width)   # what the objects add to each other
    mask = object_mask(gt, f)
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

        return (f"the negative control ({self.rig_model} rig model) is not measurably worse than the run: "
                f"psnr_objects_db margin {fmt([self.psnr_objects_margin_db])} dB "
                f"({fmt(self.psnr_objects_margin_db_per_gt)} against each ground-truth seed), cross-error margin {fmt([self.cross_error_margin])} "
                f"({fmt(self.cross_error_margin_per_gt)}); the metrics cannot tell this rig model from the run's")


def single_seed(gt: GroundTruth, i: int) -> GroundTruth:
    """The ground truth of seed ``i`` (0 or 1) alone, in both slots (its own noise then reads as 0)."""
    pick = lambda x: np.stack([x[i], x[i]])  # noqa: E731
    return GroundTruth(union=pick(gt.union), real=pick(gt.real), synthetic=pick(gt.synthetic),
                       alpha_real=gt.alpha_real, alpha_synthetic=gt.alpha_synthetic)


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


# ---- calibration against the hidden truth -----------------------------------------------------------------------

def _rig_rotation(model) -> np.ndarray:
    return rotation_xy(model.tilt) @ rotation_z(model.array.rotation)


@dataclass(frozen=True)
class CalibrationErrors:
    """A calibration against the simulated rig's hidden truth (:func:`calibration_errors`; verification only). The
    keys of ``to_json()`` are those of the project's targets (:mod:`lftransfer.calibration.targets`).

    Attributes:
        lenslet_assignment_agreement: fraction of camera pixels assigned to the right lenslet.
        ray_direction_rms_deg: each camera pixel's ray in the world, RMS angle, degrees.
        projector_mapping_rms_px: camera -> projector mapping, RMS, projector px.
        pose_position_rms_mm, pose_position_max_mm: the lenslet centres in the world, mm.
        pose_rotation_deg: the array's orientation, degrees.
        pitch_rel_error: calibrated / true pitch - 1.
        distortion_k1_rms: per-lenslet k1, RMS.
        camera_response_error, projector_response_error: responses, max, fraction of full scale.
        projector_mixing_rel_error: brightness x cross-talk, max, relative.
        black_level_error: projector black level, max, fraction of its max radiance.
        exposure_rel_error: LF camera exposure, relative.
        lenslet_centre_rms_px, lenslet_centre_max_px, lenslets_found: lenslet centres, LF camera px (None: the
            calibration has no lattice fit, e.g. read from a file).
        camera_gain_rel_rms: exposure x vignetting per pixel, RMS relative (None without vignetting).
        light_position_error_mm: the measured point lights against the true ones, the worst light, mm (None: not
            measured).
    """

    lenslet_assignment_agreement: float
    ray_direction_rms_deg: float
    projector_mapping_rms_px: float
    pose_position_rms_mm: float
    pose_position_max_mm: float
    pose_rotation_deg: float
    pitch_rel_error: float
    distortion_k1_rms: float
    camera_response_error: float
    projector_response_error: float
    projector_mixing_rel_error: float
    black_level_error: float
    exposure_rel_error: float
    lenslet_centre_rms_px: float | None = None
    lenslet_centre_max_px: float | None = None
    lenslets_found: int | None = None
    camera_gain_rel_rms: float | None = None
    light_position_error_mm: float | None = None

    def to_json(self) -> dict:
        """quantity -> error, the measured ones only (``calibration_errors.json``)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) is not None}


def calibration_errors(calibration, truth, *, true_lights=None, max_pixels: int = 200_000) -> CalibrationErrors:
    """Errors of a calibration against the simulated rig's hidden truth (verification only).

    Args:
        calibration: :class:`lftransfer.calibration.rig.Calibration`.
        truth: the true ``RigModel`` (``SimRig.truth``).
        true_lights: (3,) per point light, where it really stands, world frame, metres (the hidden world's
            ``lights``: :func:`lftransfer.sim.truth.true_light_scene`), in the scene file's order, or None.
        max_pixels: camera pixels sampled for the ray and mapping errors.

    Returns:
        :class:`CalibrationErrors`; ``light_position_error_mm`` (the worst light) where the calibration measured
        the lights and ``true_lights`` are given.
    """
    from lftransfer.calibration.radiometric import response_error

    cal = calibration.model
    out: dict = {}
    ta, ca = truth.array, cal.array
    tcam, ccam = truth.camera, cal.camera
    if calibration.lattice is not None:
        lat = calibration.lattice
        k = lat.indices[:, 0] * ta.cols + lat.indices[:, 1]
        true_px = tcam.device.ray_to_pixel(ta, k, np.tile([0.0, 0.0, 1.0], (len(k), 1)))
        err = np.linalg.norm(lat.centres - true_px, axis=1)
        out["lenslet_centre_rms_px"] = float(np.sqrt(np.mean(err ** 2)))
        out["lenslet_centre_max_px"] = float(err.max())
        out["lenslets_found"] = int(len(k))
    # camera pixels behind lenslets, a sample
    h, w = tcam.device.height, tcam.device.width
    rng = np.random.default_rng(0)
    px = np.stack([rng.uniform(0, w - 1, max_pixels), rng.uniform(0, h - 1, max_pixels)], 1)
    kt, dt = tcam.device.pixel_to_ray(ta, px)
    kc, dc = ccam.device.pixel_to_ray(ca, px)
    both = (kt >= 0) & (kc >= 0)
    same = both & (kt == kc)
    out["lenslet_assignment_agreement"] = float(same.sum() / max(both.sum(), 1))
    rt, rc = _rig_rotation(truth), _rig_rotation(cal)
    dw_t, dw_c = dt[same] @ rt.T, dc[same] @ rc.T                       # world directions
    ang = np.degrees(np.arccos(np.clip(np.sum(dw_t * dw_c, axis=1), -1, 1)))
    out["ray_direction_rms_deg"] = float(np.sqrt(np.mean(ang ** 2)))

    def to_prj(model, p):
        return apply_homography(model.projector.device.homography @ np.linalg.inv(model.camera.device.homography), p)

    inside = kt >= 0
    e = np.linalg.norm(to_prj(cal, px[inside]) - to_prj(truth, px[inside]), axis=1)
    out["projector_mapping_rms_px"] = float(np.sqrt(np.mean(e ** 2)))
    # global pose: the lenslet centres in the world, and the array's orientation
    ct, cc = ta.centres3d @ rt.T, ca.centres3d @ rc.T
    d = np.linalg.norm(ct - cc, axis=1) * 1000
    out["pose_position_rms_mm"] = float(np.sqrt(np.mean(d ** 2)))
    out["pose_position_max_mm"] = float(d.max())
    cosang = (np.trace(rc.T @ rt) - 1) / 2
    out["pose_rotation_deg"] = float(np.degrees(np.arccos(np.clip(cosang, -1, 1))))
    out["pitch_rel_error"] = float(ca.pitch / ta.pitch - 1)
    kd = np.asarray(ccam.device.distortion) - np.asarray(tcam.device.distortion)
    out["distortion_k1_rms"] = float(np.sqrt(np.mean(kd[:, 0] ** 2)))
    # radiometry
    out["camera_response_error"] = response_error(ccam.response, tcam.response)
    out["projector_response_error"] = response_error(cal.projector.response, truth.projector.response)
    tp, cp = truth.projector, cal.projector

    mt, mc = tp.max_radiance * tp.cross_talk_matrix, cp.max_radiance * cp.cross_talk_matrix
    out["projector_mixing_rel_error"] = float(np.abs(mc - mt).max() / np.abs(mt).max())
    bt = tp.max_radiance * np.asarray(tp.black_level)
    bc = cp.max_radiance * np.asarray(cp.black_level)
    out["black_level_error"] = float(np.abs(bc - bt).max() / tp.max_radiance)
    out["exposure_rel_error"] = float(ccam.exposure / tcam.exposure - 1)
    if tcam.vignetting is not None and ccam.vignetting is not None:
        ys, xs = px[inside, 1].astype(int), px[inside, 0].astype(int)
        st = tcam.exposure * tcam.vignetting[ys, xs]
        sc = ccam.exposure * ccam.vignetting[ys, xs]
        out["camera_gain_rel_rms"] = float(np.sqrt(np.mean((sc / st - 1) ** 2)))
    fits = getattr(calibration, "lights", [])
    if fits and true_lights is not None and len(true_lights) == len(fits):
        out["light_position_error_mm"] = max(float(1000 * np.linalg.norm(fit.position - np.asarray(at, float)))
                                             for fit, at in zip(fits, true_lights))
    return CalibrationErrors(**out)
