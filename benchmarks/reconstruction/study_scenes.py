"""What the studies of this folder share: their scenes and the way they print where the cross error shows.

Imported by ``projector_prefilter.py``, ``where_the_error_is.py`` and ``window.py`` (run from any folder: a
script's own folder is on Python's path).
"""

from __future__ import annotations

from pathlib import Path

from lftransfer.scenes import quick_scene
from lftransfer.scenes import builtin_scene, load_scene

HERE = Path(__file__).parent
#: Ground-truth samples per pixel at quarter resolution (at the paper's resolution the studies take 512).
GT_SPP = 8192
#: The scenes written for the reconstruction study, beside Fig. 4 (this folder's TOML files).
STUDY_SCENES = ("spheres", "cylinders", "far", "rect", "glossy")


def study_scenes(full: bool) -> list[tuple[str, object]]:
    """Fig. 4 and the study scenes as (name, scene), at the paper's resolution or, unless ``full``, a quarter."""
    scenes = [("fig4", builtin_scene("fig4")), *[(n, HERE / f"{n}.toml") for n in STUDY_SCENES]]
    return [(name, load_scene(path) if full else quick_scene(load_scene(path))) for name, path in scenes]


def by_side_cells(m, noise: str = "both") -> str:
    """The table cells of an evaluation's ``cross_by_side``: per side its error, energy ratio and error after the
    best scale, then the ground truth's noise on the real side (``noise="real"``) or on both."""
    real, syn = m.cross_by_side["real"], m.cross_by_side["synthetic"]
    cells = [f"{real.rel_error:.3f}, {real.energy_ratio:.3f}, {real.rel_error_shape:.3f}",
             f"{syn.rel_error:.3f}, {syn.energy_ratio:.3f}, {syn.rel_error_shape:.3f}",
             f"{real.gt_noise_rel:.3f}" if noise == "real" else f"{real.gt_noise_rel:.3f} / {syn.gt_noise_rel:.3f}"]
    return "| " + " | ".join(cells) + " |"
