"""The light exchange of a rendered sequence, checked against the ground truth at every verified frame.

After ``lft render --verify-every K`` has written its frames, :func:`verify_exchange` measures each verified
frame's cross-transfer error (what the two sides add to each other's appearance, against the ground truth's) and,
for a scene with an ``[effect]``, the effect (:mod:`lftransfer.sim.effects`): light field transfer's composite
(the frame's EXR) against the same transfer without the object ``by``, and the ground truth against the ground
truth without it, over the pixels of the object ``on``; x is the distance between the two objects. It writes the
cross errors into ``report.json``, and ``effect.json`` and ``effect.png`` (matplotlib: each measure against the
distance, transfer and ground truth side by side).

The cross error of a live frame is measured against the composite without exchange at the same time (a transfer
of no bounces: the projector black), for converged frames too (the same measure as ``lft run``'s).

The transfer without ``by`` is a converged N-bounce transfer at the frame's time in both modes: in live mode
it stands for what the live loop without ``by`` converges to (the object ``by`` is the one that moves). The live
loop's first N frames are not measured: it starts with a black projector and needs N frames to bring N bounces.

With the run's ``floor`` (on the simulated rig), each verified frame also gets its fidelity floor
(:mod:`lftransfer.sim.floor`, docs/architecture.md "The fidelity floor") at the frame's moment, the frame itself
scored as the floors are; with ``quiet_reference``, its ground truth is rendered until its noise on the frame's
cross term is at most a third of the error (:mod:`lftransfer.sim.reference`), and all the frame's metrics are
taken against that.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from lftransfer.runs.pipeline import RunOptions, floor_skipped, open_rig
from lftransfer.runs.reference_pool import reference_renderer
from lftransfer.runs.sequence import frame_metrics, sequence_summary
from lftransfer.reports.report import write_error_pictures
from lftransfer.imageio_utils import read_exr, write_figure, write_json
from lftransfer.transfer.bounce import TransferSettings
from lftransfer.transfer.interfaces import transfer_through

__all__ = ["EffectCurve", "EffectPoint", "ExchangeCheck", "plot_effect", "verify_exchange"]

EFFECT_JSON = "effect.json"
EFFECT_PLOT = "effect.png"
AGREEMENT = 0.2               # "matches the ground truth": within 20 % of its value (issue 11)


@dataclass(frozen=True)
class EffectPoint:
    """The effect at one verified frame.

    Attributes:
        index: frame number.
        time_s: scene time, s.
        distance_m: distance between the origins of ``on`` and ``by``, m.
        transfer: :class:`~lftransfer.sim.effects.EffectMeasure` of light field transfer.
        truth: the ground truth's.
    """

    index: int
    time_s: float
    distance_m: float
    transfer: object
    truth: object

    def to_json(self) -> dict:
        return {"index": self.index, "time_s": self.time_s, "distance_m": self.distance_m,
                "transfer": self.transfer.to_json(), "truth": self.truth.to_json()}


@dataclass
class EffectCurve:
    """The effect over a sequence's verified frames.

    Attributes:
        kind, on, by: the scene's ``[effect]``.
        points: one :class:`EffectPoint` per verified frame, in frame order.
    """

    kind: str
    on: str
    by: str
    points: list[EffectPoint] = field(default_factory=list)

    def values(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Measure name -> ((P,) transfer values, (P,) ground-truth values), NaN where undefined."""
        names = ("added_radiance",) if self.kind == "reflection" else ("contrast", "penumbra_m", "area_m2")
        get = lambda m, n: np.nan if getattr(m, n) is None else float(getattr(m, n))  # noqa: E731
        return {n: (np.array([get(p.transfer, n) for p in self.points]),
                    np.array([get(p.truth, n) for p in self.points])) for n in names}

    def worst_relative_error(self) -> dict[str, float | None]:
        """Measure name -> the largest |transfer - truth| / |truth| over the points (None: no defined point).

        A shadow's contrast is compared where the ground truth's shadow takes at least
        :data:`~lftransfer.sim.effects.MIN_CONTRAST` of the light (a fainter one is mostly noise, and its
        relative error says nothing); its penumbra is defined only there anyway."""
        from lftransfer.sim.effects import MIN_CONTRAST

        out: dict[str, float | None] = {}
        for name, (lft, gt) in self.values().items():
            ok = np.isfinite(lft) & np.isfinite(gt) & (np.abs(gt) > (MIN_CONTRAST if name == "contrast" else 0))
            out[name] = float(np.max(np.abs(lft[ok] - gt[ok]) / np.abs(gt[ok]))) if ok.any() else None
        return out

    def trend(self) -> dict[str, float | None]:
        """Measure name -> Spearman-like sign agreement: the fraction of consecutive steps in which transfer and
        truth change the same way (1.0: the same trend everywhere; None: fewer than two points)."""
        out: dict[str, float | None] = {}
        for name, (lft, gt) in self.values().items():
            d_l, d_g = np.diff(lft), np.diff(gt)
            ok = np.isfinite(d_l) & np.isfinite(d_g)
            out[name] = float(np.mean(np.sign(d_l[ok]) == np.sign(d_g[ok]))) if ok.any() else None
        return out

    def to_json(self) -> dict:
        return {"kind": self.kind, "on": self.on, "by": self.by, "agreement_bound": AGREEMENT,
                "worst_relative_error": self.worst_relative_error(), "same_trend": self.trend(),
                "points": [p.to_json() for p in self.points]}


def _without(scene, name: str):
    """A copy of ``scene`` (a whole or synthetic scene) without the synthetic object ``name``."""
    return scene.model_copy(update={"synthetic": [o for o in scene.synthetic if o.name != name]})


@dataclass
class ExchangeCheck:
    """What the verification of a sequence's light exchange found.

    Attributes:
        cross_errors: frame index -> the frame's cross-transfer error
            (:func:`~lftransfer.sim.metrics.cross_transfer_error`; None where the ground truth has no cross term);
            report.json also gets the ground truth's own noise on it (``cross_gt_noise_rel``).
        effect: the scene's effect curve, or None when it has no ``[effect]``.
    """

    cross_errors: dict[int, float | None] = field(default_factory=dict)
    effect: EffectCurve | None = None


@dataclass(frozen=True)
class _Checking:
    """What every verified frame's check shares (:func:`verify_exchange`)."""

    opened: object
    models: list               # each light field interface's rig model (one for one interface)
    scene: object              # the synthetic part, posed by the sequence's model
    depth: object              # the live frames' own depth, or None
    out: Path
    options: RunOptions
    spp: int
    quiet: bool                # a quiet reference per frame
    settings: TransferSettings
    direct: TransferSettings
    effect: object
    render: object
    parts: object
    step: Callable[[str], None]


def _check_frame(ctx: _Checking, f: dict, check: ExchangeCheck) -> None:
    """One verified frame: its cross-transfer error by side into its metrics, its fidelity floor where asked for,
    and the effect's point where the scene has one (:func:`verify_exchange`)."""
    from lftransfer.runs.sequence import read_frame_depth
    from lftransfer.sim.effects import measure_effect, object_distance, object_pixels
    from lftransfer.sim.metrics import cross_term_image, cross_transfer_error

    opened, oracle, models, ps, out = ctx.opened, ctx.opened.oracle, ctx.models, ctx.scene, ctx.out
    options = ctx.options
    rigs = opened.each_rig
    spp, settings, direct, effect, depth, step = ctx.spp, ctx.settings, ctx.direct, ctx.effect, ctx.depth, ctx.step
    render, parts = ctx.render, ctx.parts
    i, t = int(f["index"]), float(f["time_s"])
    step(f"check the exchange: frame {i}")
    world = oracle.world.at(t)
    frame = read_exr(out / "frames" / f"{i:04d}.exr")[..., :3]
    # a depth composite: the frame's own depth, so that both composites hide the same pixels
    kept = read_frame_depth(out, i)
    same = {} if kept is None else {"depth": kept[0], "view_depth": kept[1]}
    alone = transfer_through(rigs, models, ps, direct, time_s=t, **same)
    no_exchange = alone.composite_direct()
    if ctx.quiet:
        gt = _quiet_frame_truth(oracle, world, frame, no_exchange, f, spp, options.use_cache, step,
                                render=render, parts=parts)
    else:
        gt = oracle.ground_truth(spp=spp, world=world, use_cache=options.use_cache)
    cross = cross_transfer_error(frame, no_exchange, gt)
    write_error_pictures(out / "frames", f"_{i:04d}", frame, gt.image, frame - no_exchange, cross_term_image(gt))
    check.cross_errors[i] = f["metrics"]["cross_transfer_rel_error"] = cross.error
    f["metrics"]["cross_gt_noise_rel"] = cross.gt_noise
    for side, part in (cross.by_side or {}).items():          # where the error is: see cross_by_side
        f["metrics"][f"cross_{side}_rel_error"] = part.rel_error
        f["metrics"][f"cross_{side}_gt_noise_rel"] = part.gt_noise_rel
    if floor_skipped(options) is None:
        step(f"fidelity floor: frame {i}")
        converged = transfer_through(rigs, models, ps, settings, time_s=t, **(same or {"depth": depth}))
        _frame_floor(oracle, list(opened.rigs) or getattr(opened.rig, "inner", opened.rig), converged, gt, settings,
                     f, frame - no_exchange)
    if effect is None:
        return
    truth_without = oracle.ground_truth(spp=spp, world=_without(world, effect.by),
                                        use_cache=options.use_cache).image
    result = transfer_through(rigs, models, _without(ps, effect.by), settings, time_s=t,
                              **(same or {"depth": depth}))
    transfer_without = result.composite()
    pixels = object_pixels(world, effect.on)
    check.effect.points.append(EffectPoint(
        index=i, time_s=t, distance_m=object_distance(world, effect.on, effect.by),
        transfer=measure_effect(effect.kind, frame, transfer_without, pixels),
        truth=measure_effect(effect.kind, gt.image, truth_without, pixels)))


def _summarise(report: dict, check: ExchangeCheck, verified: list[dict]) -> None:
    """The verified frames' cross errors and their noise into the report's summary (the PSNRs again: a quiet
    reference changes them)."""
    values = [v for v in check.cross_errors.values() if v is not None]
    noise = [f["metrics"]["cross_gt_noise_rel"] for f in verified if f["metrics"].get("cross_gt_noise_rel") is not None]
    noisy = [f["index"] for f in verified if f["metrics"].get("cross_gt_noise_rel") is not None
             and f["metrics"].get("cross_transfer_rel_error") is not None
             and f["metrics"]["cross_gt_noise_rel"] > 0.5 * f["metrics"]["cross_transfer_rel_error"]]
    if noisy:                                   # as lft run warns: the error mostly the reference's noise
        report.setdefault("warnings", []).append(
            f"the ground truth's own noise on the cross term is more than half the cross-transfer error at "
            f"{len(noisy)} of {len(verified)} verified frames ({', '.join(map(str, noisy[:8]))}"
            f"{', ...' if len(noisy) > 8 else ''}), so those errors are mostly noise; --quiet-reference renders "
            f"each frame's reference until it is a third")
    if values and isinstance(report.get("summary"), dict):
        report["summary"]["cross_transfer_rel_error_min"] = min(values)
        report["summary"]["cross_transfer_rel_error_max"] = max(values)
        report["summary"]["cross_gt_noise_rel_max"] = max(noise) if noise else None
        report["summary"].update(sequence_summary(report["frames"]))   # the PSNRs again: a quiet reference


def verify_exchange(scene, out: str | Path, options: RunOptions, report: dict, *,
                    step: Callable[[str], None] | None = None) -> ExchangeCheck | None:
    """Check the light exchange at every verified frame of a rendered sequence, against the ground truth.

    For each verified frame (after the live loop's first N frames): its cross-transfer error (the frame's
    composite against the composite without any exchange, the projector black, at the same time), written into the
    frame's metrics in ``report.json`` as ``cross_transfer_rel_error`` beside the ground truth's own noise on it,
    ``cross_gt_noise_rel`` (and the error's range into the summary), and split by side (``cross_synthetic_rel_error``
    and ``cross_real_rel_error``, each with its ``..._gt_noise_rel``: the synthetic objects' pixels, lit by the
    captured light field, and the real ones', lit through the projector); and, for
    a scene with an ``[effect]``, the effect (module docstring), written to effect.json and effect.png; where the
    options ask for them, each frame's fidelity floor (``real_floor``, ``synthetic_floor``, ``fidelity_floor``,
    ``floor_transfer``, ``transfer_over_floor`` in its metrics, the whole in its ``fidelity_floor``) and a quiet
    reference (its ``reference``; ``reference_spp``, ``reference_noise_over_error`` in its metrics). The transfer
    without ``by`` prefilters with the depth the live frames used (``state/depth.npz``) where there is one: a depth
    measured anew differs by the capture's noise, which showed as a faint "shadow" where there was none.

    Args:
        scene: the ``SceneConfig`` the sequence was rendered from.
        out: the sequence's folder (its ``frames/NNNN.exr`` and ``report.json``).
        options: the sequence's :class:`RunOptions` (the simulated rig, its truth seed, ground-truth samples,
            ``floor``, ``quiet_reference``).
        report: the sequence's report (the frames with metrics are the verified ones; ``key.settings`` the
            transfer settings); updated and rewritten. The rig model is the sequence's: its calibration file,
            ``out/calibration.json``, the oracle or the nominal model
            (:func:`~lftransfer.runs.sequence.acquire_model`).
        step: called with a message before each frame.

    Returns:
        The :class:`ExchangeCheck`, or None when no frame was verified (or the rig has no ground truth).
    """
    from lftransfer.runs.sequence import acquire_model, read_depth

    effect = scene.effect
    warmup = int(report["key"]["settings"]["bounces"]) if report.get("mode") == "live" else 0
    verified = [f for f in report.get("frames", []) if f.get("metrics") and int(f["index"]) >= warmup]
    for f in report.get("frames", []):          # verified during the warm-up: no cross error, and why
        if f.get("metrics") and int(f["index"]) < warmup:
            f["metrics"].setdefault("undefined", {})["cross_transfer_rel_error"] = (
                f"a warm-up frame: the live loop adds one exchange per frame, so frames 0 to {warmup - 1} do not "
                f"yet have the {warmup} bounces the sequence asks for (frames from {warmup} on are checked)")
    if not verified:
        return None
    out = Path(out)
    step = step or (lambda _msg: None)
    settings = TransferSettings(**{**report["key"]["settings"], "bounce_views": False})
    direct = TransferSettings(**{**report["key"]["settings"], "bounce_views": False, "bounces": 0})
    check = ExchangeCheck(effect=EffectCurve(kind=effect.kind, on=effect.on, by=effect.by) if effect else None)
    resolved = options.resolve(scene)
    spp = resolved.gt_spp
    opened = open_rig(scene, options, interfaces=True)
    try:
        oracle = opened.oracle
        if oracle is None:
            return None
        known = acquire_model(opened, scene, options, out, True, step)
        ps = known.scene
        depth = read_depth(out)         # the live frames' own depth: both sides prefilter alike
        with reference_renderer(options.cluster if resolved.quiet_reference else None,
                                use_cache=options.use_cache, step=step) as (render, parts):
            ctx = _Checking(opened, known.each_model, ps, depth, out, options, spp, resolved.quiet_reference, settings,
                            direct, effect, render, parts, step)
            for f in verified:
                _check_frame(ctx, f, check)
    finally:
        opened.close()
    _summarise(report, check, verified)
    write_json(out / "report.json", report)
    if check.effect is not None:
        write_json(out / EFFECT_JSON, check.effect.to_json())
        plot_effect(check.effect, out / EFFECT_PLOT, title=scene.source.stem if scene.source else None)
    return check


def _quiet_frame_truth(oracle, world, frame: np.ndarray, no_exchange: np.ndarray, record: dict, spp: int,
                       use_cache: bool, step: Callable[[str], None], *, render=None, parts: int = 1):
    """A verified frame's ground truth rendered until its noise on the frame's cross term is at most a third of
    the error (:mod:`lftransfer.sim.reference`); the frame's PSNRs are taken again against it, and what it reached
    goes to the frame's ``reference``."""
    from lftransfer.sim.metrics import metric_factor
    from lftransfer.sim.reference import cross_term_judge

    gt, reference = oracle.quiet_ground_truth(cross_term_judge(frame, no_exchange), spp=spp, world=world,
                                              multiple=metric_factor(frame.shape[1]), use_cache=use_cache,
                                              parts=parts, render=render, progress=step)
    record["reference"] = reference.to_json()
    record["metrics"].update(frame_metrics(frame, gt), reference_spp=reference.spp,
                             reference_noise_over_error=reference.ratio)
    return gt


def _frame_floor(oracle, rig, converged, gt, settings: TransferSettings, record: dict, cross: np.ndarray) -> None:
    """A verified frame's fidelity floor at its moment (the real side's search started from ``converged``, the
    frame's own ``cross`` term scored), into its record: the whole as ``fidelity_floor``, the numbers in its
    metrics."""
    floor = oracle.fidelity_floor(rig, converged, gt, settings, time_s=float(record["time_s"]), cross=cross)
    record["fidelity_floor"] = floor.to_json()
    record["metrics"].update(real_floor=floor.real_floor, synthetic_floor=floor.synthetic_floor,
                             fidelity_floor=floor.floor, floor_transfer=floor.transfer,
                             transfer_over_floor=floor.transfer_over_floor)


_LABELS = {"added_radiance": ("radiance added to {on} by {by}", "W m$^{{-2}}$ sr$^{{-1}}$", 1.0),
           "contrast": ("shadow of {by} on {on}: contrast", "fraction of the light", 1.0),
           "penumbra_m": ("shadow of {by} on {on}: penumbra width", "mm", 1000.0),
           "area_m2": ("shadow of {by} on {on}: area taking half the light", "cm$^2$", 1e4)}


def plot_effect(curve: EffectCurve, path: str | Path, *, title: str | None = None) -> Path:
    """Plot each measure of ``curve`` against the distance: light field transfer beside the ground truth, with
    the band of +-20 % around the ground truth (the agreement the issue asks for)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    values = curve.values()
    x = np.array([p.distance_m for p in curve.points]) * 1000.0
    fig, axes = plt.subplots(1, len(values), figsize=(5.2 * len(values), 3.8), squeeze=False)
    for ax, (name, (lft, gt)) in zip(axes[0], values.items()):
        label, unit, scale = _LABELS[name]
        ax.fill_between(x, (1 - AGREEMENT) * gt * scale, (1 + AGREEMENT) * gt * scale, color="0.85",
                        label=f"ground truth $\\pm${AGREEMENT:.0%}")
        ax.plot(x, gt * scale, "o-", color="black", label="ground truth (path traced)")
        ax.plot(x, lft * scale, "s--", color="tab:red", label="light field transfer")
        ax.set_xlabel(f"distance from {curve.by} to {curve.on} (mm)")
        ax.set_ylabel(unit)
        ax.set_title(label.format(on=curve.on, by=curve.by), fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return write_figure(path, fig)
