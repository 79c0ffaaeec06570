"""A run's verdict: its headline metric, how sure it is, what the rig allows, and one line that reads them.

The headline is the cross-transfer error (docs/architecture.md, "Verification"); its confidence is the reference's
own noise on the cross term (``cross_gt_noise_rel``); the yardstick is the fidelity floor, the best any algorithm
could do through this rig, with the transfer scored as the floor is and the reference's noise taken off both
(``fidelity_floor``). The reading, in order:

- not verified (no hidden truth to compare with): says why;
- a cross term under :data:`TOO_SMALL` of the image over the objects: too small to judge;
- a floor: "within N x of what this rig allows" (judged even where the reference is noisy, since the floor's
  comparison takes the noise off);
- no floor and the reference's noise over :data:`NOISY` of the error: not judged, with what would judge it;
- else the error with its noise.
"""

from __future__ import annotations

__all__ = ["NOISY", "TOO_SMALL", "verdict"]

TOO_SMALL = 0.01
"""A cross term below this share of the image (``cross_term_rel_size``) is too small to judge: its error is a
ratio of small numbers, and the picture does not show it."""
NOISY = 0.5
"""Without a floor, an error whose reference is noisier than this share of it is not judged (the warning's limit)."""


def _floor_reading(e: float, n: float | None, floor: dict) -> str:
    over = floor["transfer_over_floor"]
    noise = f", the reference's noise ({n:.2g}) taken off both" if n is not None else ""
    where = "at what this rig allows" if over <= 1.1 else f"within {over:.3g}x of what this rig allows"
    return (f"{where}: the cross error scored as the floor is {floor['transfer']:.3g}, the floor "
            f"{floor['floor']:.3g}{noise} (cross error {e:.3g})")


def verdict(report: dict) -> dict:
    """The verdict of a run (or a verified frame) from its report's metrics.

    Args:
        report: a run's report (``cross_transfer_rel_error``, ``cross_gt_noise_rel``, ``cross_term_rel_size``,
            ``fidelity_floor``, ``undefined_metrics``, ``verification``).

    Returns:
        ``{"cross_transfer_rel_error", "reference_noise", "cross_term_rel_size", "transfer_over_floor", "judged",
        "reading"}``: the headline, its confidence, the share of the image it is about, the ratio to the floor
        (None where there is none), whether the reading judges the run, and the reading, one line.
    """
    e, n = report.get("cross_transfer_rel_error"), report.get("cross_gt_noise_rel")
    size = report.get("cross_term_rel_size")
    floor = report.get("fidelity_floor") or {}
    over = floor.get("transfer_over_floor")
    undefined = report.get("undefined_metrics") or {}
    out = {"cross_transfer_rel_error": e, "reference_noise": n, "cross_term_rel_size": size,
           "transfer_over_floor": over, "judged": False}
    if e is None:
        why = undefined.get("cross_transfer_rel_error") or report.get("verification") or "no ground truth"
        return {**out, "reading": f"not judged: no cross error ({why})"}
    if size is not None and size < TOO_SMALL:
        return {**out, "reading": f"the cross term here is {100 * size:.2g} % of the image over the objects: too "
                                  f"small to judge (cross error {e:.3g})"}
    if over is not None and floor.get("transfer") is not None and floor.get("floor") is not None:
        return {**out, "judged": True, "reading": _floor_reading(e, n, floor)}
    if n is not None and n > NOISY * e:
        return {**out, "reading": f"not judged: the reference's own noise ({n:.2g}) is more than half the cross "
                                  f"error ({e:.3g}); --quiet-reference (or a larger --reference-budget) renders it "
                                  f"quieter"}
    reason = undefined.get("fidelity_floor", "no floor")
    noise = f" +- {n:.2g} (the reference's noise)" if n is not None else ""
    return {**out, "judged": True, "reading": f"cross error {e:.3g}{noise}; no floor to compare with ({reason})"}
