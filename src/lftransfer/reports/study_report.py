"""The report of a study (``lft study``): ``study.png`` and ``study.html``.

The figure has one panel per headline metric (the cross-transfer error, the PSNR over the objects): a group of
bars per scene, a bar per setting at the mean over the seeds, the seeds' range as an error bar, and the ground
truth's own noise on the cross term as a dotted mark (an error below it is not measurable). The page is the
``study.html`` template (:mod:`lftransfer.reports.templating`) with the figure and the table.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from lftransfer.reports import figures
from lftransfer.reports.templating import environment
from lftransfer.imageio_utils import write_bytes, write_text

__all__ = ["PANELS", "pitch_figure", "study_figure", "write_study_report"]

PANELS = ("cross_transfer_rel_error", "psnr_objects_db")


def study_figure(result):
    """Bars per scene and setting (mean over the seeds, their range as error bars) of :data:`PANELS`.

    Args:
        result: ``lftransfer.runs.study.StudyResult``.

    Returns:
        A matplotlib Figure (Agg canvas).
    """
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
        label, unit, lower, _ = result.metrics[metric]
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


def pitch_figure(result):
    """The rig designer's plot (a study whose settings redesign the lens array, ``array_pitch_mm``): per scene, the
    cross-transfer error, the transfer scored as the floors are, the fidelity floor and each side's floor against
    the lens pitch (means over the seeds), with the ground truth's own noise.

    Returns:
        A matplotlib Figure (Agg canvas), or None where the settings do not all set a pitch.
    """
    if not result.pitches or set(result.pitches) != set(result.settings):
        return None
    order = sorted(result.settings, key=result.pitches.get)
    pitch = np.array([result.pitches[s] for s in order])
    lines = [("cross_transfer_rel_error", "cross-transfer error", "C0", "-"),
             ("cross_gt_noise_rel", "ground truth's own noise", "k", ":")]
    if result.floor:
        lines += [("floor_transfer", "transfer, scored as the floors", "C1", "-"), ("floor", "floor", "C2", "-"),
                  ("real_floor", "real side's floor", "C2", "--"), ("synthetic_floor", "synthetic side's floor",
                                                                      "C2", "-.")]
    fig = figures.new_figure(4.2 * len(result.scenes) + 0.6, 3.4)
    axes = np.atleast_1d(fig.subplots(1, len(result.scenes)))
    for ax, scene in zip(axes, result.scenes):
        for metric, label, colour, style in lines:
            rows = {r["setting"]: r["mean"] for r in result.summary(metric) if r["scene"] == scene}
            y = np.array([np.nan if rows.get(s) is None else rows[s] for s in order])
            ax.plot(pitch, y, style, color=colour, marker="o", ms=3, label=label)
        ax.set_title(Path(scene).stem if scene.endswith(".toml") else scene)
        ax.set_xlabel("lens pitch (mm)")
        ax.set_ylabel("relative error")
        ax.set_ylim(0, None)
    axes[0].legend(loc="best", fontsize=7)
    return fig


def write_study_report(out: Path, result) -> None:
    """``study.png`` and ``study.html`` (one self-contained page: the figure embedded, the table, every cell), and
    ``pitch.png`` where the settings redesign the lens array (:func:`pitch_figure`)."""
    metrics = result.metrics

    fig = study_figure(result)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    write_bytes(out / "study.png", buf.getvalue())
    pitch = pitch_figure(result)
    if pitch is not None:
        buf = io.BytesIO()
        pitch.savefig(buf, format="png", dpi=110)
        write_bytes(out / "pitch.png", buf.getvalue())
    head = ["scene", "setting"] + [f"{short} ({unit})" for _, unit, _, short in metrics.values()]
    tables = {m: {(r["scene"], r["setting"]): r for r in result.summary(m)} for m in metrics}
    rows = [[scene, setting] + [tables[m][(scene, setting)] for m in metrics]
            for scene in result.scenes for setting in result.settings]
    cells = [[c.scene, str(c.seed), c.setting] + [c.metrics.get(m) for m in metrics] + [c.seconds]
             for c in result.cells]
    page = environment().get_template("study.html").render(
        title=f"Study: {result.title}",
        subtitle=f"{len(result.scenes)} scenes x {len(result.seeds)} hidden truths x {len(result.settings)} settings; "
                 f"rig model {result.rig_model}; {result.bounces} bounces",
        sections=["Summary", "Every cell"], result=result, figure=figures.embed(fig, "Mean over the hidden truths "
        "(bars), their range (error bars); dotted: the ground truth's own noise on the cross term.", fmt="svg"),
        head=head, rows=rows, metrics=list(metrics), units=[m[1] for m in metrics.values()],
        legend=[(m[3], m[0], m[1]) for m in metrics.values()],
        cell_head=["scene", "seed", "setting"] + [m[3] for m in metrics.values()] + ["transfer (s)"],
        cells=cells,
        pitch_figure=None if pitch is None else figures.embed(
            pitch, "Against the lens pitch (the array redesigned over the same extent, the cameras keeping their "
                   "pixels per lenslet): the error, the floors (both sides and each), the ground truth's noise.",
            fmt="svg"))
    write_text(out / "study.html", page)
