"""The report of a study (``lft study``): ``study.png`` and ``study.html``.

The figure has one panel per headline metric (the cross-transfer error, the PSNR over the objects): a group of
bars per scene, a bar per setting at the mean over the seeds, the seeds' range as an error bar, and the ground
truth's own noise on the cross term as a dotted mark (an error below it is not measurable). The page is the
``study.html`` template (:mod:`lftransfer.app.templating`) with the figure and the table.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from lftransfer.app import figures
from lftransfer.app.templating import environment
from lftransfer.imageio_utils import write_bytes, write_text

__all__ = ["PANELS", "study_figure", "write_study_report"]

PANELS = ("cross_transfer_rel_error", "psnr_objects_db")


def study_figure(result):
    """Bars per scene and setting (mean over the seeds, their range as error bars) of :data:`PANELS`.

    Args:
        result: ``lftransfer.app.study.StudyResult``.

    Returns:
        A matplotlib Figure (Agg canvas).
    """
    from lftransfer.app.study import METRICS

    n_scenes, n_set = len(result.scenes), len(result.settings)
    fig = figures.new_figure(max(5.0, 1.3 + 0.55 * n_scenes * n_set) * len(PANELS) / 1.6, 3.4)
    axes = fig.subplots(1, len(PANELS))
    width = 0.8 / max(n_set, 1)
    x = np.arange(n_scenes)
    colours = [f"C{i}" for i in range(n_set)]
    for ax, metric in zip(np.atleast_1d(axes), PANELS):
        rows = {(r["scene"], r["setting"]): r for r in result.summary(metric)}
        for j, setting in enumerate(result.settings):
            mean, lo, hi = (np.array([np.nan if rows[(s, setting)][k] is None else rows[(s, setting)][k]
                                      for s in result.scenes]) for k in ("mean", "min", "max"))
            pos = x - 0.4 + width * (j + 0.5)
            ax.bar(pos, mean, width * 0.9, color=colours[j], label=setting,
                   yerr=np.nan_to_num(np.stack([mean - lo, hi - mean])), capsize=2, error_kw={"lw": 0.8})
        if metric == "cross_transfer_rel_error":
            noise = {r["scene"]: r["mean"] for r in result.summary("cross_gt_noise_rel") if r["mean"] is not None}
            for i, s in enumerate(result.scenes):
                if s in noise:
                    ax.hlines(noise[s], i - 0.42, i + 0.42, colors="k", linestyles=":", lw=1.2,
                              label="ground truth's own noise" if i == 0 else None)
        label, unit, lower, _ = METRICS[metric]
        ax.set_title(f"{label} ({'lower' if lower else 'higher'} is better)")
        ax.set_ylabel(unit)
        ax.set_xticks(x, [Path(s).stem if s.endswith(".toml") else s for s in result.scenes],
                      rotation=20 if n_scenes > 3 else 0)
        ax.grid(axis="x", visible=False)
        if metric == "psnr_objects_db":
            finite = [r["min"] for r in rows.values() if r["min"] is not None]
            if finite:
                ax.set_ylim(max(0.0, min(finite) - 3.0), None)
    np.atleast_1d(axes)[0].legend(loc="best")
    return fig


def write_study_report(out: Path, result) -> None:
    """``study.png`` and ``study.html`` (one self-contained page: the figure embedded, the table, every cell)."""
    from lftransfer.app.study import METRICS

    fig = study_figure(result)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    write_bytes(out / "study.png", buf.getvalue())
    head = ["scene", "setting"] + [f"{short} ({unit})" for _, unit, _, short in METRICS.values()]
    tables = {m: {(r["scene"], r["setting"]): r for r in result.summary(m)} for m in METRICS}
    rows = [[scene, setting] + [tables[m][(scene, setting)] for m in METRICS]
            for scene in result.scenes for setting in result.settings]
    cells = [[c.scene, str(c.seed), c.setting] + [c.metrics.get(m) for m in METRICS] + [c.seconds]
             for c in result.cells]
    page = environment().get_template("study.html").render(
        title=f"Study: {result.title}",
        subtitle=f"{len(result.scenes)} scenes x {len(result.seeds)} hidden truths x {len(result.settings)} settings; "
                 f"rig model {result.rig_model}; {result.bounces} bounces",
        sections=["Summary", "Every cell"], result=result, figure=figures.embed(fig, "Mean over the hidden truths "
        "(bars), their range (error bars); dotted: the ground truth's own noise on the cross term.", fmt="svg"),
        head=head, rows=rows, metrics=list(METRICS), units=[m[1] for m in METRICS.values()],
        legend=[(m[3], m[0], m[1]) for m in METRICS.values()],
        cell_head=["scene", "seed", "setting"] + [m[3] for m in METRICS.values()] + ["transfer (s)"],
        cells=cells)
    write_text(out / "study.html", page)
