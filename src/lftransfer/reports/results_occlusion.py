"""docs/results.md's tables of a run where real objects hide synthetic ones, or the reverse (``lft run occlusion
--composite depth``, ``lft run occlusion_reverse``): both composites on the pixels where one side hides the other,
and the real depth that the depth composite used, per source."""

from __future__ import annotations

from lftransfer.reports.results_format import fixed

__all__ = ["FALSE_FRACTION", "OCCLUSION_GAIN_DB", "UNHIDDEN_SLACK_DB", "occlusion_tables"]

OCCLUSION_GAIN_DB = 10.0       # the depth composite beats the over operator on the hidden pixels by at least this
UNHIDDEN_SLACK_DB = 1.5        # ... and its objects' PSNR is within this of the over operator's where nothing is hidden
FALSE_FRACTION = 0.03          # ... and at most this share of the real depth's pixels see no real object


def _verdict(ok: bool | None) -> str:
    return "n/a" if ok is None else "met" if ok else "**not met**"


def occlusion_tables(stored) -> list[str]:
    """The tables of a stored ``lft run --composite depth`` report (kind ``occlusion``)."""
    r = stored.data
    occ, depth = r.get("occlusion"), r.get("real_depth")
    out: list[str] = []
    if not occ:
        return ["Neither a real nor a synthetic object hides the other in this run's ground truth.", ""]
    ahead = occ.get("synthetic_front_pixels")
    reverse = "" if ahead is None else f", {ahead} a synthetic object in front of a real one (\"synthetic in front\")"
    out += [f"{occ['hidden_pixels']} pixels (at the metrics' resolution) show a real object in front of a synthetic "
            f"one (\"hidden\"){reverse}. The composites are of the same transfer; \"unhidden\" is the objects' "
            "other pixels.", "",
            "| composite | PSNR, hidden pixels | PSNR, synthetic in front | PSNR, objects | PSNR, objects unhidden | "
            "cross-transfer error |", "|---|---|---|---|---|---|"]
    for name, label in (("over", "over operator (the paper's)"), ("depth", "depth-aware"),
                        ("true_depth", "depth-aware, given the twin's true depth")):
        m = occ.get(name)
        if m:
            out.append(f"| {label} | {fixed(m['psnr_hidden_db'], 2, ' dB')} | "
                       f"{fixed(m.get('psnr_synthetic_front_db'), 2, ' dB')} | {fixed(m['psnr_objects_db'], 2)} dB | "
                       f"{fixed(m['psnr_objects_unhidden_db'], 2)} dB | {fixed(m['cross_transfer_rel_error'], 3)} |")
    out.append("")
    d, o = occ.get("depth"), occ.get("over")
    if d and o:
        gain = occ.get("depth_gain_hidden_db")
        ok_gain = None if gain is None else gain >= OCCLUSION_GAIN_DB
        ref = o["psnr_objects_unhidden_db"]
        ok_whole = None if ref is None or d["psnr_objects_db"] is None else \
            d["psnr_objects_db"] >= ref - UNHIDDEN_SLACK_DB
        out += ["| target | measured | verdict |", "|---|---|---|"]
        if occ["hidden_pixels"]:
            out.append(f"| depth composite at least {OCCLUSION_GAIN_DB:g} dB better than the over operator on the "
                       f"hidden pixels | {('-' if gain is None else f'{gain:+.2f}')} dB | {_verdict(ok_gain)} |")
        front_d, front_o = d.get("psnr_synthetic_front_db"), o.get("psnr_synthetic_front_db")
        if front_d is not None and front_o is not None:
            lag = front_d - front_o
            out.append(f"| where a synthetic object is in front (the over operator is right there), the depth "
                       f"composite within {UNHIDDEN_SLACK_DB:g} dB of it | {lag:+.2f} dB | "
                       f"{_verdict(lag >= -UNHIDDEN_SLACK_DB)} |")
        out.append(f"| its objects' PSNR within {UNHIDDEN_SLACK_DB:g} dB of the scene without occlusion (the over "
                   f"operator where nothing is hidden) | {fixed(d['psnr_objects_db'], 2)} dB against "
                   f"{fixed(ref, 2)} dB | {_verdict(ok_whole)} |")
        if d.get("psnr_objects_unhidden_db") is not None and ref is not None:
            lag = d["psnr_objects_unhidden_db"] - ref
            out.append(f"| ... over the objects' pixels where nothing is hidden | "
                       f"{fixed(d['psnr_objects_unhidden_db'], 2)} dB against {fixed(ref, 2)} dB | "
                       f"{_verdict(lag >= -UNHIDDEN_SLACK_DB)} |")
        false = (depth or {}).get("false_fraction")
        if false is not None:
            out.append(f"| at most {100 * FALSE_FRACTION:g} % of the real depth's pixels off the real objects | "
                       f"{100 * false:.1f} % | {_verdict(false < FALSE_FRACTION)} |")
        out.append("")
    if depth:
        out += [f"The real scene's depth in the view camera (`{depth['source']}`), against the twin's true depth:", "",
                "| source | pixels with a depth | of the real pixels covered | of its pixels off the real objects | "
                "error, median | error, 95th percentile | within 3 sigma | taken by the fusion |",
                "|---|---|---|---|---|---|---|---|"]
        rows = [(name, s) for name, s in (depth.get("sources") or {}).items()] + [("used (fused)", depth)]
        for name, s in rows:
            out.append(f"| {name} | {fixed(100 * s['known_fraction'], 1)} % | "
                       f"{fixed(None if s.get('coverage') is None else 100 * s['coverage'], 0)} % | "
                       f"{fixed(None if s.get('false_fraction') is None else 100 * s['false_fraction'], 0)} % | "
                       f"{fixed(s.get('error_mm_median'), 1)} mm | {fixed(s.get('error_mm_p95'), 0)} mm | "
                       f"{fixed(None if s.get('within_3_sigma') is None else 100 * s['within_3_sigma'], 0)} % | "
                       f"{'-' if 'chosen_fraction' not in s else fixed(100 * s['chosen_fraction'], 0) + ' %'} |")
        out.append("")
    return out
