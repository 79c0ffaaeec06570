"""Scoring a run made through the device twin against the ground truth of the twin's hidden world.

A run through ``--rig hardware:twin.toml`` does not know the real scene (the hardware path never does); it keeps
the view images its metrics need (``views.npz``, :func:`lftransfer.runs.run_folder.write_views`). The twin's manifest
names the scene and the truth seed, so the same world can be built again here and path traced from the view camera,
and the run scored with the very metrics ``lft run`` computes on the in-process rig
(:func:`lftransfer.sim.metrics.evaluate`), and its calibration against the true rig
(:func:`lftransfer.sim.calibration_errors.calibration_errors`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from lftransfer.composite import composite

__all__ = ["SavedViews", "TwinScore", "score_views"]


@dataclass(frozen=True)
class _View:
    rgb: np.ndarray
    alpha: np.ndarray | None = None


@dataclass(frozen=True)
class _Bounce:
    synthetic_view: _View


@dataclass(frozen=True)
class SavedViews:
    """The images of a run that its metrics are computed from, read back from ``views.npz`` (the attributes
    :func:`lftransfer.sim.metrics.evaluate` reads of a transfer result)."""

    real_view: np.ndarray
    real_view_direct: np.ndarray
    synthetic_view: _View
    bounces: tuple
    frames: tuple[np.ndarray, np.ndarray] | None = None     # the run's own composite and composite_direct

    def composite(self) -> np.ndarray:
        """The run's final frame (its own composite; a file without it: the over operator of its views)."""
        if self.frames is not None:
            return self.frames[0]
        return composite(self.synthetic_view.rgb, self.synthetic_view.alpha, self.real_view)

    def composite_direct(self) -> np.ndarray:
        """The run's frame without the exchange, as :meth:`composite`."""
        if self.frames is not None:
            return self.frames[1]
        return composite(self.bounces[0].synthetic_view.rgb, self.synthetic_view.alpha, self.real_view_direct)

    @classmethod
    def read(cls, path: str | Path) -> "SavedViews":
        """Read ``views.npz``; ValueError naming the file and the missing array."""
        path = Path(path)
        if not path.is_file():
            raise ValueError(f"{path}: no such file; the run kept no view images (runs on a rig with a known truth "
                             "are scored when they run)")
        with np.load(path) as z:
            names = ("real_view", "real_view_direct", "synthetic_rgb", "synthetic_alpha", "synthetic_direct_rgb")
            missing = [n for n in names if n not in z.files]
            if missing:
                raise ValueError(f"{path}: {', '.join(missing)}: missing (expected the arrays {', '.join(names)})")
            a = {n: np.asarray(z[n], np.float32) for n in names}
            frames = (tuple(np.asarray(z[n], np.float32) for n in ("composite", "composite_direct"))
                      if "composite" in z.files and "composite_direct" in z.files else None)
        return cls(real_view=a["real_view"], real_view_direct=a["real_view_direct"],
                   synthetic_view=_View(a["synthetic_rgb"], a["synthetic_alpha"]),
                   bounces=(_Bounce(_View(a["synthetic_direct_rgb"])),), frames=frames)


@dataclass(frozen=True)
class TwinScore:
    """A run scored against the twin's truth.

    Attributes:
        metrics: :class:`lftransfer.sim.metrics.Evaluation`.
        ground_truth: the :class:`lftransfer.sim.ground_truth.GroundTruth` rendered.
        calibration_errors: :class:`lftransfer.sim.calibration_errors.CalibrationErrors` of the run's calibration
            file, or None where the run has none.
        noisy: the ground truth's noise verdict on the cross term, or None where it is quiet enough.
    """

    metrics: object
    ground_truth: object
    calibration_errors: object | None
    noisy: object | None


def score_views(views: SavedViews, scene, truth_seed: int | None, *, gt_spp: int, use_cache: bool = True,
                calibration_file: str | Path | None = None,
                progress: Callable[[str], None] | None = None) -> TwinScore:
    """Score a run's views against the world the twin built from ``scene`` and ``truth_seed``.

    Args:
        views: the run's views.
        scene: the scene the twin served (``--quick`` applied as it was there).
        truth_seed: the twin's truth seed.
        gt_spp: samples per pixel of each ground-truth render.
        use_cache: read and write the ground-truth cache.
        calibration_file: the run's calibration file, scored against the true rig, or None.
        progress: called before each render.
    """
    from lftransfer.calibration.interfaces import read_calibration
    from lftransfer.sim.metrics import evaluate, gt_noise_verdict
    from lftransfer.sim.oracle import hidden_oracle

    oracle = hidden_oracle(scene, truth_seed)
    world = oracle.world
    h, w = views.real_view.shape[:2]
    if (w, h) != tuple(world.view.resolution):
        raise ValueError(f"the run's views are {w}x{h}, the twin's scene renders {world.view.resolution[0]}x"
                         f"{world.view.resolution[1]} (was the twin served with --quick and the run not, or the "
                         "reverse?)")
    gt = oracle.ground_truth(spp=gt_spp, use_cache=use_cache, progress=progress)
    metrics = evaluate(views, gt)
    errors = None
    if calibration_file is not None and Path(calibration_file).is_file():
        cal = read_calibration(calibration_file, scene.synthetic_part())    # one interface's, or several
        errors = oracle.calibration_errors(cal)
    return TwinScore(metrics=metrics, ground_truth=gt, calibration_errors=errors,
                     noisy=gt_noise_verdict(metrics, gt_spp))
