"""How much memory a run needs, estimated from the scene before any work, and the limit it must fit.

The estimate is linear in the sizes a scene sets: pixels of the LF camera, the projector and the view camera,
light field samples (lenslets x U x V), bounces, and whether the run calibrates. Its coefficients are peak
resident sizes measured on this project's runs (``llvm_ad_rgb``, 2 CPU cores, November 2026, one size changed at
a time from a tiny scene that peaks at 265 MB: each view pixel adds about 700 bytes with its ground truth, each
LF camera pixel 310 bytes and 500 more when calibrating, each projector pixel 160 bytes, each light field sample
350 bytes), rounded up. ``lft demo --quick`` (calibration, two bounces, both lighting models, ground truth) is
estimated at 0.52 GB and peaked at 0.48 GB; the full Fig. 4 run is estimated at 3.7 GB.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass

from lftransfer.choices import DEFAULT_BOUNCES

__all__ = ["MemoryEstimate", "MemoryLimitError", "available_memory", "check_memory", "estimate_memory",
           "format_bytes", "parse_size"]

BASE_BYTES = 300e6                 # Mitsuba, Dr.Jit and the interpreter with a tiny scene
PER_VIEW_PIXEL = 700.0             # view renders, composite, ground truth (6 renders) and metrics
PER_VIEW_PIXEL_BOUNCE = 50.0       # each bounce's real and synthetic views
PER_CAMERA_PIXEL = 310.0           # simulated capture, decoder maps, raw and decoded images
PER_CAMERA_PIXEL_CALIBRATION = 500.0   # calibration captures (Gray codes, sweeps, brackets) and fits
PER_PROJECTOR_PIXEL = 160.0        # encoder maps and projector images
PER_LIGHT_FIELD_SAMPLE = 350.0     # light fields per bounce, the renderers' ray batches


class MemoryLimitError(ValueError):
    """A run that would need more memory than the limit; the message gives the estimate and the limit."""


@dataclass(frozen=True)
class MemoryEstimate:
    """Peak memory a run is expected to need.

    Attributes:
        total: bytes.
        parts: bytes per cause (``base``, ``view``, ``lf_camera``, ``calibration``, ``projector``,
            ``light_field``), summing to ``total``.
    """

    total: int
    parts: dict[str, int]

    def largest(self) -> str:
        """The part that needs the most besides the program itself, as ``"the view camera 7.0 TB"``."""
        names = {"base": "the program", "view": "the view camera", "lf_camera": "the LF camera",
                 "calibration": "calibration captures", "projector": "the projector", "light_field": "light fields"}
        parts = {k: v for k, v in self.parts.items() if k != "base"} or self.parts
        key = max(parts, key=parts.get)
        return f"{names.get(key, key)} {format_bytes(self.parts[key])}"


def estimate_memory(scene, *, bounces: int = DEFAULT_BOUNCES, calibrate: bool = True) -> MemoryEstimate:
    """Estimate the peak memory of a run on ``scene`` (see the module's notes for where the numbers come from).

    Args:
        scene: ``SceneConfig`` or ``SyntheticScene`` (its ``rig``, ``view``).
        bounces: number of bounces N.
        calibrate: whether the run calibrates the rig first.

    Returns:
        MemoryEstimate.
    """
    rig, view = scene.rig, scene.view
    view_px = view.resolution[0] * view.resolution[1]
    cam_px = rig.lf_camera[0] * rig.lf_camera[1]
    prj_px = rig.projector[0] * rig.projector[1]
    samples = rig.rows * rig.cols * rig.angular_samples ** 2
    parts = {
        "base": BASE_BYTES,
        "view": view_px * (PER_VIEW_PIXEL + PER_VIEW_PIXEL_BOUNCE * bounces),
        "lf_camera": cam_px * PER_CAMERA_PIXEL,
        "calibration": cam_px * PER_CAMERA_PIXEL_CALIBRATION if calibrate else 0.0,
        "projector": prj_px * PER_PROJECTOR_PIXEL,
        "light_field": samples * PER_LIGHT_FIELD_SAMPLE * (1 + 0.25 * bounces),
    }
    parts = {k: int(v) for k, v in parts.items()}
    return MemoryEstimate(total=sum(parts.values()), parts=parts)


def available_memory() -> int:
    """Memory the machine can give a new run now: ``MemAvailable`` of ``/proc/meminfo``, else the physical
    memory (bytes)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not a POSIX system
        return 1 << 62


_UNITS = {"": 1, "k": 1e3, "m": 1e6, "g": 1e9, "t": 1e12, "ki": 2 ** 10, "mi": 2 ** 20, "gi": 2 ** 30, "ti": 2 ** 40}


def parse_size(text: str) -> int:
    """``"64G"``, ``"512MB"``, ``"1.5 GiB"``, ``"2000000"`` -> bytes.

    Raises:
        ValueError: not a positive size.
    """
    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+)\s*([kmgt]i?)?b?\s*", str(text), flags=re.IGNORECASE)
    if not m:
        raise ValueError(f"expected a size such as 16G, 512M or 2000000000 (bytes), got {text!r}")
    value = float(m.group(1)) * _UNITS[(m.group(2) or "").lower()]
    if not value >= 1:
        raise ValueError(f"expected a positive size, got {text!r}")
    return int(value)


def format_bytes(n: float) -> str:
    """Bytes in the largest decimal unit that keeps a number >= 1: ``"3.6 GB"``."""
    for unit, size in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= size:
            return f"{n / size:.1f} {unit}"
    return f"{int(n)} B"


def check_memory(estimate: MemoryEstimate, limit: int | None = None) -> int:
    """Refuse a run whose estimate exceeds the limit.

    Args:
        estimate: from :func:`estimate_memory`.
        limit: bytes; None: :func:`available_memory`.

    Returns:
        The limit used.

    Raises:
        MemoryLimitError: with the estimate, its largest part and the limit.
    """
    given = limit is not None
    limit = available_memory() if limit is None else int(limit)
    if estimate.total > limit:
        source = "--max-memory" if given else "memory available now"
        raise MemoryLimitError(
            f"this run needs about {format_bytes(estimate.total)} of memory (most for {estimate.largest()}), "
            f"more than the limit of {format_bytes(limit)} ({source}); make the scene smaller (or --quick), or "
            f"raise the limit with --max-memory SIZE on a bigger machine")
    return limit
