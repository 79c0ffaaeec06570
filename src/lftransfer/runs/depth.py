"""``lft depth``: the disparity and depth of a light field given as a folder of sub-aperture views, scored against a
ground truth where one is given (:mod:`lftransfer.lightfield.disparity`, :mod:`lftransfer.lightfield.view_grid`)."""

from __future__ import annotations

import time
from pathlib import Path

import cv2
import numpy as np

from lftransfer.imageio_utils import write_json, write_png
from lftransfer.lightfield.disparity import disparity_to_depth, estimate_disparity, score_disparity
from lftransfer.lightfield.view_grid import read_pfm, read_view_grid, write_pfm

__all__ = ["FILES", "estimate_folder"]

FILES = ("disparity.pfm", "disparity.png", "depth.pfm", "depth.png", "confidence.png", "report.json")


def _colour(values: np.ndarray) -> np.ndarray:
    """(H, W) values as an (H, W, 3) uint8 picture (turbo colour map over their 1st to 99th percentile; NaN
    black)."""
    finite = np.isfinite(values)
    lo, hi = (np.percentile(values[finite], (1, 99)) if finite.any() else (0.0, 1.0))
    x = np.clip((np.where(finite, values, lo) - lo) / max(hi - lo, 1e-12), 0.0, 1.0)
    rgb = cv2.applyColorMap(np.round(x * 255).astype(np.uint8), cv2.COLORMAP_TURBO)[..., ::-1]
    return np.where(finite[..., None], rgb, 0).astype(np.uint8)


def estimate_folder(folder: str | Path, out: str | Path, *, truth: str | Path | None = None, steps: int = 64,
                    progress=None) -> dict:
    """Estimate the disparity of the light field in ``folder`` and write :data:`FILES` into ``out``.

    Args:
        folder: the light field (``input_CamNNN.png`` and ``parameters.cfg``).
        out: the output folder (made if missing).
        truth: a ground-truth disparity map (PFM), to score against.
        steps: candidate disparities over the folder's ``disp_min`` to ``disp_max``.
        progress: called with a message before each stage.

    Returns:
        The report (``report.json``): the views' shape, the range and candidates, the seconds the estimate took,
        the depth's range, and with ``truth`` the benchmark's scores (``badpix_0.07``, ``mse_x100``).
    """
    say = progress or (lambda _m: None)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    say("read the views")
    grid = read_view_grid(folder)
    say(f"estimate the disparity ({steps} candidates)")
    t0 = time.perf_counter()
    est = estimate_disparity(grid.views, disp_min=grid.disp_min, disp_max=grid.disp_max, steps=steps)
    seconds = time.perf_counter() - t0
    depth = disparity_to_depth(est.disparity, grid.baseline_m, grid.focal_px, grid.focus_m)
    say("write the maps")
    write_pfm(out / "disparity.pfm", est.disparity)
    write_pfm(out / "depth.pfm", np.nan_to_num(depth, nan=np.inf))
    write_png(out / "disparity.png", _colour(est.disparity))
    write_png(out / "depth.png", _colour(depth))
    write_png(out / "confidence.png", np.round(np.clip(est.confidence, 0, 1) * 255).astype(np.uint8)[..., None]
              .repeat(3, axis=-1))
    report = {"folder": str(folder), "views": list(grid.views.shape), "disp_range": [grid.disp_min, grid.disp_max],
              "steps": steps, "seconds": round(seconds, 2),
              "depth_m": [float(np.nanmin(depth)), float(np.nanmax(depth))] if np.isfinite(depth).any() else None,
              "scores": None, "truth": None}
    if truth is not None:
        report["truth"] = str(truth)
        report["scores"] = score_disparity(est.disparity, read_pfm(truth))
    write_json(out / "report.json", report)
    return report
