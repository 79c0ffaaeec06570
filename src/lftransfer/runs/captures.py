"""Photographs from the simulated rig as a physical rig's cameras would leave them on disk (``lft sim capture``), so
that the calibration steps that read image files (``lft calibrate lenslets``) can be tried without hardware, and
checked against the hidden truth the simulated rig keeps.

- ``spots``: the LF camera under a collimated on-axis source (one spot per lenslet);
- ``white``: the LF camera under the white diffuser (each lenslet's sub-image);
- ``scene``: the LF camera and the view camera looking at the real scene (projector black).

The LF camera's codes are written as 16-bit PNG (its ``bits``-bit codes scaled to the full 16 bits, as a camera's
driver stores them); the view camera's linear radiance as EXR and, for looking at, an sRGB PNG. With ``truth``
the true lenslet centres in the LF camera (``truth_centres.csv``: where the on-axis ray through each lenslet lands,
the same CSV as ``lft calibrate lenslets`` writes) go beside them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lftransfer.imageio_utils import write_exr, write_png, write_png16, write_text
from lftransfer.rig.requests import Collimator, RealScene, WhiteField

__all__ = ["KINDS", "capture_images", "write_codes_png"]

KINDS = ("spots", "white", "scene")


def write_codes_png(path: Path, codes: np.ndarray, bits: int) -> Path:
    """Camera codes (H, W, 3) or (H, W) of ``bits`` bits as a 16-bit PNG (scaled to the full 16 bits), atomically."""
    scaled = np.asarray(codes, np.uint32) << (16 - int(bits))
    return write_png16(path, np.clip(scaled, 0, 65535).astype(np.uint16))


def _true_centres(model) -> str:
    """CSV (header ``x,y``) of the pixel where the on-axis ray through each lenslet's centre lands, LF camera px, in
    the lenslets' row-major order."""
    array = model.array
    k = np.arange(array.K)
    px = model.camera.device.ray_to_pixel(array, k, np.tile([0.0, 0.0, 1.0], (array.K, 1)))
    return "x,y\n" + "".join(f"{x:.4f},{y:.4f}\n" for x, y in np.asarray(px, np.float64))


def capture_images(scene, kind: str, out: Path, *, truth_seed: int | None = 0, capture_spp: int | None = None,
                   truth: bool = False) -> list[Path]:
    """Photograph ``kind`` (:data:`KINDS`) through the simulated rig of ``scene`` and write the images into ``out``.

    Args:
        scene: the whole scene (the simulated rig takes its devices and real objects).
        kind: "spots", "white" or "scene".
        out: the folder (made if missing).
        truth_seed: the hidden truth's seed (None: the rig built exactly as its file says).
        capture_spp: rays per LF camera pixel (None: the default).
        truth: also write the true lenslet centres (``truth_centres.csv``).

    Returns:
        The files written.
    """
    from lftransfer.runs.pipeline import RunOptions
    from lftransfer.runs.rigs import RigSpec, open_rig

    if kind not in KINDS:
        raise ValueError(f"kind: expected one of {', '.join(KINDS)}, got {kind!r}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    options = RunOptions(rig=RigSpec.parse("sim"), truth_seed=truth_seed,
                         **({} if capture_spp is None else {"capture_spp": capture_spp}))
    opened = open_rig(scene, options)
    rig, written = opened.rig, []
    try:
        rig.project(rig.info.black())
        rig.setup({"spots": Collimator(), "white": WhiteField(), "scene": RealScene(0.0)}[kind])
        frame = rig.capture_lf()
        written.append(write_codes_png(out / f"lf_{kind}.png", frame.codes, frame.bits))
        if kind == "scene":
            view = rig.capture_view().radiance
            written.append(write_exr(out / "view.exr", view))
            written.append(write_png(out / "view.png", np.clip(view / max(float(view.max()), 1e-12), 0.0, 1.0)))
        if truth:
            written.append(write_text(out / "truth_centres.csv", _true_centres(opened.oracle.model)))
    finally:
        rig.close()
    return written
