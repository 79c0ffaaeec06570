"""docs/results.md's tables of a light probe scene (``lft run probe``): the synthetic objects lit by the room the
mirror ball shows, against one point light at the probe's brightest direction (``--direct-light point``, the same
rig and calibration), and the recovered map against the twin's room."""

from __future__ import annotations

from lftransfer.reports.results_format import by_side, fixed

__all__ = ["probe_tables"]


def probe_tables(stored) -> list[str]:
    """The tables of a stored light probe comparison (kind ``probe``: ``data["probe"]`` and ``data["point"]``,
    two ``report.json``)."""
    runs = [(name, stored.need(name)) for name in ("probe", "point")]
    out = ["Both runs are of the same rig, calibration and ground truth; only the synthetic objects' direct light "
           "differs. \"Synthetic pixels\" are those where a synthetic object is seen, \"real pixels\" the objects' "
           "others.", "",
           "| direct light | PSNR, objects | PSNR, synthetic pixels | PSNR, real pixels | cross-transfer error | "
           "cross error, synthetic side | cross error, real side | ground truth's noise on the cross term |",
           "|---|---|---|---|---|---|---|---|"]
    labels = {"probe": "the light probe's map", "point": "one point light at the probe's brightest direction"}
    for name, r in runs:
        out.append(f"| {labels[name]} | {fixed(r.get('psnr_objects_db'), 2)} dB | "
                   f"{fixed(by_side(r, 'psnr_by_side', 'synthetic'), 2)} dB | "
                   f"{fixed(by_side(r, 'psnr_by_side', 'real'), 2)} dB | {fixed(r.get('cross_transfer_rel_error'), 3)} | "
                   f"{fixed(by_side(r, 'cross_by_side', 'synthetic', 'rel_error'), 3)} | "
                   f"{fixed(by_side(r, 'cross_by_side', 'real', 'rel_error'), 3)} | "
                   f"{fixed(r.get('cross_gt_noise_rel'), 3)} |")
    out.append("")
    probe = stored.need("probe", "direct_light", "probe")
    truth = probe.get("against_truth")
    if truth:
        out += ["The map the mirror ball gave, against the twin's room (read along the same directions):", "",
                "| map | measured share of the sphere | brightest spot off the room's | power over the measured "
                "directions | quiet texels, median error |", "|---|---|---|---|---|",
                f"| {probe['map'][0]} x {probe['map'][1]} | {fixed(100 * truth['measured_share'], 1)} % | "
                f"{fixed(truth['brightest_direction_error_deg'], 2)} degrees | "
                f"{fixed(100 * (truth['power_ratio'] - 1), 1, ' %')} off | "
                f"{fixed(100 * truth['texel_rel_error_median'], 3)} % |", ""]
    side = stored.need("probe", "cross_by_side", "real")
    floor = (stored.need("probe").get("fidelity_floor") or {}).get("real") or {}
    if side and side.get("energy_ratio") is not None:
        text = (f"On the real side the exchange carries {fixed(100 * side['energy_ratio'], 0)} % of the true cross "
                "term's light: with the projector dark the array's panel shades the real objects from the room "
                "behind it; the transfer projects the room its lenslets see behind the synthetic objects, within "
                "their window (about 26.6 degrees off the array's normal), stronger by what the window leaves out "
                "(for surfaces facing the array; docs/architecture.md, \"The light probe\").")
        if floor.get("floor") is not None:
            text += (f" The real side's fidelity floor (the best projector image) is {fixed(floor['floor'], 3)} "
                     f"against the transfer's {fixed(floor.get('transfer'), 3)}, scored alike.")
        out += [text, ""]
    return out
