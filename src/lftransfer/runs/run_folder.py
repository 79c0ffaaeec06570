"""A run's output folder: it always says whether it is complete, and never mixes two runs.

``status.json`` is written first (``running``) and last (``complete``, ``failed`` with the error, or
``interrupted``). Before a run writes anything else, the files an earlier run left there (``report.json``,
images, calibration files) and temporary files of interrupted writes are removed, so a folder never shows an
old report beside new images; files of the run's own inputs (a ``--calibration`` file kept in the folder) stay.
"""

from __future__ import annotations

import os
import time
import traceback
from contextlib import contextmanager
from pathlib import Path
from typing import Iterable

from lftransfer.reports.report import write_json

__all__ = ["OUTPUT_FILES", "STATUS_FILE", "VIEWS_FILE", "clear_run_folder", "remove_temporaries", "tracked_run",
           "write_status", "write_views"]

STATUS_FILE = "status.json"
OUTPUT_FILES = ("report.json", "composite.png", "composite.exr", "ground_truth.png", "ground_truth.exr",
                "bounces.png", "captured_lf.png", "projected_lf.png", "interfaces.png", "probe.png", "probe.exr",
                "calibration.json",
                "calibration_report.html", "calibration_errors.json")


def _is_temporary(name: str) -> bool:
    """A temporary file of :mod:`lftransfer.imageio_utils`'s atomic writers (``.<stem>.<random><suffix>``) for
    one of the run folder's files, or a left-over write probe."""
    if name.startswith(".lft-probe-"):
        return True
    for final in (*OUTPUT_FILES, STATUS_FILE):
        stem, suffix = os.path.splitext(final)
        if name.startswith(f".{stem}.") and name.endswith(suffix) and len(name) > len(stem) + len(suffix) + 2:
            return True
    return False


def remove_temporaries(out: str | Path) -> list[Path]:
    """Remove temporary files of interrupted writes from a run folder; returns what was removed."""
    out = Path(out)
    removed = []
    if out.is_dir():
        for p in out.iterdir():
            if p.is_file() and _is_temporary(p.name):
                p.unlink(missing_ok=True)
                removed.append(p)
    return removed


def clear_run_folder(out: str | Path, keep: Iterable[str | Path] = ()) -> list[Path]:
    """Remove an earlier run's outputs and any temporary files from ``out`` (which need not exist).

    Args:
        out: the run folder.
        keep: files that must stay (the run's own inputs, e.g. its ``--calibration`` file).

    Returns:
        The files removed.
    """
    out = Path(out)
    kept = {Path(k).resolve() for k in keep}
    removed = remove_temporaries(out)
    for name in OUTPUT_FILES:
        p = out / name
        if p.is_file() and p.resolve() not in kept:
            p.unlink()
            removed.append(p)
    return removed


@contextmanager
def tracked_run(out: str | Path, rig: str, *, interrupted: str = "interrupted (Ctrl-C)"):
    """The status of the run inside the block: ``complete`` when it ends, ``interrupted`` (with ``interrupted``
    as the error) on Ctrl-C, ``failed`` with the error and a short traceback on any other exception (which is
    raised again); temporary files of interrupted writes are removed either way. ``running`` is the caller's to
    write first (before it clears the folder)."""
    try:
        yield
    except KeyboardInterrupt:
        write_status(out, "interrupted", rig=rig, error=interrupted)
        raise
    except BaseException as exc:
        write_status(out, "failed", rig=rig, error=f"{type(exc).__name__}: {exc}",
                     traceback=traceback.format_exc(limit=8).splitlines())
        raise
    finally:
        remove_temporaries(out)
    write_status(out, "complete", rig=rig)


def write_status(out: str | Path, state: str, **extra) -> Path:
    """Write ``status.json`` (atomically): ``state`` is "running", "complete", "failed" or "interrupted"."""
    return write_json(Path(out) / STATUS_FILE, {"state": state, "time": time.strftime("%Y-%m-%dT%H:%M:%S"), **extra})


VIEWS_FILE = "views.npz"


def write_views(path: Path, result) -> Path:
    """The view images a run's metrics are computed from, for scoring it later against a truth the run did not
    know (``lft twin score``): ``real_view``, ``real_view_direct``, ``synthetic_rgb``, ``synthetic_alpha`` and
    ``synthetic_direct_rgb`` ((H, W, 3) / (H, W) float32 radiance and coverage), and the run's own frames after
    and without the exchange, ``composite`` and ``composite_direct`` (by the run's composite)."""
    from lftransfer.imageio_utils import write_npz

    return write_npz(path, real_view=result.real_view, real_view_direct=result.real_view_direct,
                     synthetic_rgb=result.synthetic_view.rgb, synthetic_alpha=result.synthetic_view.alpha,
                     synthetic_direct_rgb=result.bounces[0].synthetic_view.rgb, composite=result.composite(),
                     composite_direct=result.composite_direct())
