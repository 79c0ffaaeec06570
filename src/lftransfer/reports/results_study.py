"""docs/results.md's tables of a stored study (``lft study``'s ``study.json``), and the rig designer's answer: the
lens pitch at which a scene's cross-transfer error reaches a target, from the pitch study's measured curve."""

from __future__ import annotations

import math

import numpy as np

from lftransfer.reports.results_format import num, table

__all__ = ["TARGET_ERROR", "pitch_for", "study_tables"]

TARGET_ERROR = 0.05             # "what array gives a cross error of 0.05?"


def _means(data: dict, metric: str, scene: str) -> dict[str, float]:
    """setting -> the metric's mean over the seeds for ``scene`` (settings without a value left out)."""
    rows = (data.get("summary") or {}).get(metric) or []
    return {r["setting"]: r["mean"] for r in rows if r.get("scene") == scene and r.get("mean") is not None}


def pitch_for(pitches: dict[str, float], errors: dict[str, float], target: float = TARGET_ERROR) -> dict | None:
    """The pitch at which the error reaches ``target``, from a power law fitted to the measured (pitch, error)
    points (least squares on log error against log pitch).

    Returns:
        {"pitch_mm", "exponent", "extrapolated" (outside the measured pitches), "points"}, or None with fewer than
        two positive points or an error that does not grow with the pitch.
    """
    pts = sorted((pitches[s], e) for s, e in errors.items() if s in pitches and e is not None and e > 0)
    if len(pts) < 2:
        return None
    x, y = np.log([p for p, _ in pts]), np.log([e for _, e in pts])
    slope, intercept = np.polyfit(x, y, 1)
    if not slope > 0:
        return None
    pitch = float(math.exp((math.log(target) - intercept) / slope))
    return {"pitch_mm": pitch, "exponent": float(slope), "points": len(pts),
            "extrapolated": not (pts[0][0] <= pitch <= pts[-1][0])}


def study_tables(data: dict, scene_rigs: dict | None = None) -> list[str]:
    """A study's summary table (per scene and setting, the mean over the seeds of every metric it carries) and,
    for a pitch study, the pitch each scene needs for :data:`TARGET_ERROR` (the transfer's error scored as the
    floors are, and the floor's)."""
    summary = data.get("summary") or {}
    metrics = [m for m in ("cross_transfer_rel_error", "cross_gt_noise_rel", "floor_transfer", "floor", "real_floor",
                           "synthetic_floor", "psnr_objects_db") if m in summary]
    pitches = data.get("pitches") or {}
    out: list[str] = []
    rows = []
    for scene in data.get("scenes", []):
        for setting in sorted(data.get("settings", []), key=lambda s: pitches.get(s, 0.0)):
            values = [_means(data, m, scene).get(setting) for m in metrics]
            rows.append([scene, setting, num(pitches.get(setting)), *(num(v) for v in values)])
    out += table(["scene", "setting", "pitch (mm)", *(f"`{m}`" for m in metrics)], rows)
    if pitches and "floor_transfer" in summary:
        answers = []
        for scene in data.get("scenes", []):
            for metric, what in (("floor_transfer", "the transfer"), ("floor", "the floor (any algorithm)")):
                fit = pitch_for(pitches, _means(data, metric, scene))
                if fit is None:
                    answers.append([scene, what, "no fit (the error does not grow with the pitch here)", "", ""])
                    continue
                answers.append([scene, what, num(fit["pitch_mm"]), num(fit["exponent"]),
                                "extrapolated" if fit["extrapolated"] else "within the measured pitches"])
        out += [f"The pitch at which the error reaches {TARGET_ERROR} (a power law error = c pitch^k fitted to the "
                "points above: the transfer scored as the floors are, and the floor; both with the ground truth's "
                "noise taken off):", ""]
        out += table(["scene", "error of", f"pitch for {TARGET_ERROR} (mm)", "exponent k", ""], answers)
        out += ["![The cross-transfer error, the transfer scored as the floors are, the fidelity floor and each "
                "side's floor against the lens pitch](images/pitch_study.png)", ""]
    return out
