"""Number and table formatting of docs/results.md (:mod:`lftransfer.reports.results`)."""

from __future__ import annotations

import math

__all__ = ["by_side", "db", "fixed", "median_p95", "num", "table"]


def by_side(report: dict, table: str, side: str, key: str | None = None):
    """A report's per-side entry (``report[table][side]``, e.g. ``cross_by_side``'s ``"real"``), or its ``key``;
    None where the report has none."""
    entry = (report.get(table) or {}).get(side)
    return entry if key is None or entry is None else entry.get(key)


def num(v, digits: int = 3) -> str:
    """A number to ``digits`` significant digits (no exponent between 1e-4 and 1e6); '-' for None / NaN."""
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int):
        return str(v)
    if not isinstance(v, float):
        return str(v)
    if not math.isfinite(v):
        return "-" if math.isnan(v) else str(v)
    if v == 0:
        return "0"
    if 0.999 <= abs(v) < 1:                    # an agreement of 0.99997 is not 1.000
        return f"{v:.{digits + 3}f}"
    mag = math.floor(math.log10(abs(v)))
    if -4 <= mag < 6:
        return f"{v:.{max(digits - 1 - mag, 0)}f}"
    return f"{v:.{digits - 1}e}"


def fixed(v, decimals: int, unit: str = "") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return f"{v:.{decimals}f}{unit}"


def db(v) -> str:
    return fixed(v, 2, " dB")


def table(header: list[str], rows: list[list[str]]) -> list[str]:
    cell = lambda s: str(s).replace("|", "\\|").replace("\n", " ")  # noqa: E731
    out = ["| " + " | ".join(cell(h) for h in header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(cell(c) for c in row) + " |" for row in rows]
    return out + [""]


def median_p95(x) -> str:
    """``median (p95)`` in whole units of a {"median", "p95"} spread; '-' for none."""
    return "-" if not isinstance(x, dict) else f"{fixed(x.get('median'), 0)} ({fixed(x.get('p95'), 0)})"


def resolution_text(res: dict) -> str:
    """A run's ``resolution`` in words: lenslets, devices, directions per lenslet."""
    parts = []
    if "lenslets" in res:
        parts.append(f"{res['lenslets'][0]} x {res['lenslets'][1]} {res.get('lattice', '')} lenslets".replace("  ",
                                                                                                           " "))
    for key, label in (("lf_camera", "LF camera"), ("projector", "projector"), ("view", "view")):
        if key in res:
            parts.append(f"{label} {res[key][0]} x {res[key][1]}")
    if "angular_samples" in res:
        parts.append(f"{res['angular_samples']} x {res['angular_samples']} directions per lenslet")
    return ", ".join(parts)


def surface_solve_text(solve: dict) -> str:
    """The bench's surface solve (``BenchResult.surface_solve``) in words: warm frames (ms, steps), the cold start,
    the last frame's misfit against a converged solve and the box light field's."""
    warm, steps = solve["warm_ms"], solve["warm_iterations"]
    out = (f"warm {warm['median']:.1f} ms (max {warm['max']:.1f}; {steps['median']:g} steps, at most "
           f"{steps['max']})" if warm else "no warm frame")
    if solve["cold_ms"] is not None:
        out += f"; cold {solve['cold_ms']:.0f} ms ({solve['cold_iterations']} steps, in the warm-up)"
    last = solve.get("last_frame")
    if last is not None:
        out += (f"; last frame's misfit {last['misfit']:.3f} (converged {last['converged_misfit']:.3f}, box light "
                f"field {last['box_misfit']:.3f})")
    if solve["cold_in_timed"]:
        out += f"; {solve['cold_in_timed']} timed frames started cold"
    return out
