"""What every step of the lenslet calibration shares: its error, the ideal lattice, argument checks, homographies.

See :mod:`lftransfer.calibration.lenslets` for the procedure and the conventions (pixel coordinates, lattice
indices, ideal lattice coordinates).
"""

from __future__ import annotations

import math

import numpy as np

from lftransfer.optics.geometry import apply_homography

_SQRT3_2 = math.sqrt(3.0) / 2.0
_ROW_STEP = {"hex": _SQRT3_2, "rect": 1.0}


class NoSpotsError(ValueError):
    """No lenslet lattice could be found in the image (no spots, too few, or no consistent lattice)."""


def lattice_coordinates(indices: np.ndarray, lattice: str) -> np.ndarray:
    """Ideal lattice coordinates (unit pitch) of lattice indices.

    Args:
        indices: ``(N, 2)`` integer ``(row, col)`` lattice indices.
        lattice: ``"hex"`` or ``"rect"``.

    Returns:
        ``(N, 2) float64`` ``(u, v)``: ``u = col + (row % 2) / 2`` (hex) or ``col`` (rect), ``v = row * sqrt(3) / 2``
        (hex) or ``row`` (rect); u grows with image x, v with image y.
    """
    _check_lattice(lattice)
    idx = np.asarray(indices, dtype=np.int64).reshape(-1, 2)
    r, c = idx[:, 0], idx[:, 1]
    u = c + (0.5 * (r % 2) if lattice == "hex" else 0.0)
    return np.stack([u.astype(np.float64), r * _ROW_STEP[lattice]], axis=1)


def _check_lattice(lattice: str) -> None:
    if lattice not in _ROW_STEP:
        raise ValueError(f"lattice must be 'hex' or 'rect', got {lattice!r}")


def _check_shape(expected_shape) -> tuple[int, int]:
    try:
        rows, cols = (int(v) for v in expected_shape)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"expected_shape must be (rows, cols), got {expected_shape!r}") from exc
    if rows < 1 or cols < 1:
        raise ValueError(f"expected_shape must be positive (rows, cols), got {expected_shape!r}")
    return rows, cols


def _as_grey(image: np.ndarray) -> np.ndarray:
    arr = np.asarray(image)
    if arr.ndim == 2 and arr.dtype.kind == "f":
        img = arr.astype(np.float64)
    else:
        from lftransfer.imageio_utils import to_grey

        img = to_grey(arr)
    if min(img.shape) < 3:
        raise ValueError(f"image of shape {img.shape} is too small to hold lenslet spots")
    return np.nan_to_num(img, nan=0.0, posinf=0.0, neginf=0.0)


def _apply(h: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Homography ``h`` applied to ``(N, 2)`` points."""
    return apply_homography(h, pts)
