"""docs/results.md's section on one run of the pipeline (``lft demo``, ``lft run``): its report.json as tables
(:mod:`lftransfer.reports.results`)."""

from __future__ import annotations

from lftransfer.reports.results_format import db, fixed, num, resolution_text, table

__all__ = ["METRICS", "demo_tables"]

METRICS = (("cross_transfer_rel_error", "cross-transfer error", num), ("psnr_db", "psnr_db", db),
           ("psnr_objects_db", "psnr_objects_db", db))


def demo_tables(s) -> list[str]:
    """A run's report.json as docs/results.md shows it: the headline metrics, each choice against its alternative,
    the negative control, the quiet reference, the fidelity floor, the surface solve's ablations, the cross term by
    side, the bounces, the calibration's errors, the stages' wall time and the warnings."""
    out: list[str] = []
    for section in (_demo_headline, _demo_choices, _demo_control, _demo_floor, _demo_ablations, _demo_details):
        out += section(s)
    return out


def _demo_headline(s) -> list[str]:
    d = s.data
    for key, _, _ in METRICS:
        s.need(key)
    out: list[str] = []
    rows = [[f"`{k}`", f(d[k])] for k, _, f in METRICS]
    for key, f in (("psnr_db_direct_only", db), ("psnr_objects_db_direct_only", db), ("gt_noise_psnr_db", db),
                   ("cross_gt_noise_rel", num), ("cross_term_rel_size", num), ("projector_clipped_fraction", num),
                   ("lf_camera_saturated_fraction", num)):
        if key in d:
            rows.append([f"`{key}`", f(d[key])])
    res = d.get("resolution") or {}
    settings = ", ".join(f"{k} {d[k]}" for k in ("lighting_model", "reconstruction", "projection", "window",
                                                  "rig_model", "renderer", "variant", "gt_spp", "truth_seed")
                         if d.get(k) is not None)
    if res:
        out += [f"Resolution: {resolution_text(res)}. Settings: {settings}.", ""]
    out += table(["quantity", "value"], rows)
    if d.get("undefined_metrics"):
        out += table(["undefined metric", "why"], [[f"`{k}`", v] for k, v in d["undefined_metrics"].items()])
    return out


def _demo_choices(s) -> list[str]:
    d = s.data
    comp = []
    for key, label, used in (("by_lighting_model", "lighting model", "lighting_model"),
                             ("by_reconstruction", "reconstruction", "reconstruction"),
                             ("by_projection", "projection", "projection"), ("by_window", "window", "window")):
        for choice, m in (d.get(key) or {}).items():
            tag = " (the run's)" if choice == d.get(used) else ""
            comp.append([f"{label}: {choice}{tag}",
                         *(f(s.need(key, choice, k)) for k, _, f in METRICS)])
    if not comp:
        return []
    return ["Each choice against its alternative, the rest as in the run "
            "(`by_lighting_model`, `by_reconstruction`, `by_projection`, `by_window`):", "",
            *table(["choice", "cross-transfer error", "psnr_db", "psnr_objects_db"], comp)]


def _demo_control(s) -> list[str]:
    d, out = s.data, []
    nc = d.get("negative_control")
    if isinstance(nc, dict):
        out += ["Negative control (`negative_control`: the same rig run with the rig file's nominal values, "
                "no calibration):", ""]
        out += table(["rig model", "cross-transfer error", "psnr_objects_db", "run better by (cross error)",
                      "run better by (psnr_objects_db)", "measurably worse"],
                     [[s.need("negative_control", "rig_model"), num(s.need("negative_control",
                                                                            "cross_transfer_rel_error")),
                       db(s.need("negative_control", "psnr_objects_db")), num(nc.get("cross_error_margin")),
                       db(nc.get("psnr_objects_margin_db")), num(nc.get("measurably_worse"))]])
    elif "negative_control" in d:
        why = (d.get("undefined_metrics") or {}).get("negative_control", "not run")
        out += [f"Negative control: not run ({why}).", ""]
    ref = d.get("reference")
    if isinstance(ref, dict):
        out += [f"Quiet reference (`reference`): {num(ref.get('spp'))} samples per pixel in the objects' box over "
                f"{num(ref.get('rounds'))} rounds ({num(ref.get('samples'))} camera samples in all); the ground "
                f"truth's noise on the cross term {num(ref.get('noise'))}, {num(ref.get('ratio'))} of the error "
                f"(target {num(ref.get('target'))}: {'met' if ref.get('met') else 'not met'}).", ""]
    return out


def _demo_floor(s) -> list[str]:
    d, out = s.data, []
    floor = d.get("fidelity_floor")
    if isinstance(floor, dict):
        out += ["The fidelity floor (`fidelity_floor`, docs/architecture.md \"The fidelity floor\"): each side's best "
                "through this rig against the transfer, both scored against the ground truth's second seed with its "
                "noise taken off, in the cross-transfer error's units:", ""]
        rows = []
        for side in ("real", "synthetic"):
            v = floor.get(side)
            if isinstance(v, dict):
                rows.append([side, num(v.get("floor")), num(v.get("transfer")), num(v.get("relaxed")),
                             num(v.get("noise")), num(v.get("pixels"))])
        rows.append(["both (root sum of squares)", num(floor.get("floor")), num(floor.get("transfer")), "", "", ""])
        out += table(["side", "floor", "transfer", "relaxed optimum (real)", "reference noise", "pixels"], rows)
        out += [f"Transfer / floor (`transfer_over_floor`): {num(floor.get('transfer_over_floor'))}.", ""]
    elif "fidelity_floor" in d:
        why = (d.get("undefined_metrics") or {}).get("fidelity_floor", "not found")
        out += [f"Fidelity floor: not found ({why}).", ""]
    return out


def _demo_ablations(s) -> list[str]:
    """The surface solve's ablations (`surface_ablations`): the run, the same solve given the true depth, and given
    the measured depth moved (a negative control)."""
    ab = s.data.get("surface_ablations")
    if not isinstance(ab, dict):
        return []
    labels = {"run": "the run (measured depth)", "oracle_surface": "the true depth (oracle)",
              "depth_moved_2cm": "the measured depth moved 2 cm (negative control)"}
    rows = [[label, num(ab[k].get("cross_transfer_rel_error")), num(ab[k].get("real_side")),
             num(ab[k].get("synthetic_side"))] for k, label in labels.items() if isinstance(ab.get(k), dict)]
    out = ["The projection solved against the measured surface, given other depths (`surface_ablations`; the sides "
           "scored as the fidelity floor scores them):", ""]
    out += table(["depth", "cross-transfer error", "real side", "synthetic side"], rows)
    if ab.get("depth_share") is not None:
        out += [f"The real side's error the measured depth adds over the true one (`depth_share`): "
                f"{num(ab['depth_share'])}.", ""]
    return out


def _demo_details(s) -> list[str]:
    d, out = s.data, []
    sides = d.get("cross_by_side") or {}
    if sides:
        out += ["The cross term by side (`cross_by_side`; real: light the synthetic objects sent through the "
                "projector; synthetic: light of the captured light field):", ""]
        out += table(["side", "rel_error", "energy_ratio", "rel_error_shape", "gt_noise_rel", "pixels"],
                     [[side, *(num(v.get(k)) for k in ("rel_error", "energy_ratio", "rel_error_shape",
                                                       "gt_noise_rel", "pixels"))]
                      for side, v in sides.items()])
    if d.get("bounces"):
        out += ["Energy per bounce (W through the array; `bounces`):", ""]
        out += table(["bounce", "real_energy", "synthetic_energy", "projector_gain"],
                     [[num(b.get("index", i)), num(b.get("real_energy")), num(b.get("synthetic_energy")),
                       num(b.get("projector_gain"))] for i, b in enumerate(d["bounces"])])
    cal = d.get("calibration_errors")
    if isinstance(cal, dict) and cal:
        out += ["Calibration against the simulated rig's hidden truth (`calibration_errors`):", ""]
        out += table(["quantity", "error"], [[f"`{k}`", num(v)] for k, v in cal.items()])
    if d.get("timings_s"):
        out += ["Wall time by stage (`timings_s`, seconds):", ""]
        out += table(["stage", "s"], [[f"`{k}`", fixed(v, 2)] for k, v in d["timings_s"].items()])
    if d.get("warnings"):
        out += ["Warnings of the run:", ""] + [f"- {w}" for w in d["warnings"]] + [""]
    return out
