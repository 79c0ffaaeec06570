"""Calibration photographs: reading 8/16-bit PNG or TIFF files and turning camera arrays into grey images.

Every calibration step that works on image files (``lft calibrate lenslets`` and the like) reads them through
:func:`read_image`, and callers that already hold an array (e.g. the simulated rig's ``(H, W, 3) uint16``
12-bit codes) go through :func:`to_grey`, so both paths give the same thing: a ``(H, W) float64`` grey image
normalised to [0, 1] by the full scale of the data (colour -> mean of the channels, alpha dropped).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from lftransfer.imageio_utils import native_messages

__all__ = ["CalibrationImageError", "read_image", "to_grey"]

_EXPECTED = "an 8- or 16-bit PNG or TIFF image (grey, RGB or RGBA)"
_FULL_SCALE = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}


class CalibrationImageError(ValueError):
    """A calibration image could not be read or has an unsupported format; the message names the file if any."""


def to_grey(image: np.ndarray, levels: float | None = None) -> np.ndarray:
    """Grey image normalised by the full scale of the data.

    Args:
        image: ``(H, W)``, ``(H, W, 1)``, ``(H, W, 2)`` (grey + alpha), ``(H, W, 3)`` (colour) or ``(H, W, 4)``
            (colour + alpha) array of ``uint8``, ``uint16`` or floating-point values. The channel order does
            not matter (colour is averaged); alpha is dropped.
        levels: the value that stands for full scale (e.g. ``4095`` for 12-bit codes stored in ``uint16``).
            Default: 255 for ``uint8``, 65535 for ``uint16``, 1 for floating point; other dtypes need it.

    Returns:
        ``(H, W) float64`` grey image, ``image / levels`` (in [0, 1] for data within full scale).

    Raises:
        CalibrationImageError: unsupported dtype or shape, empty image, or a non-positive ``levels``.
    """
    arr = np.asarray(image)
    if arr.dtype.kind not in "uif":
        raise CalibrationImageError(f"unsupported pixel type {arr.dtype}: expected uint8, uint16 or float values")
    if levels is None:
        if arr.dtype.kind == "f":
            levels = 1.0
        elif arr.dtype in _FULL_SCALE:
            levels = _FULL_SCALE[arr.dtype]
        else:
            raise CalibrationImageError(f"unsupported pixel type {arr.dtype}: expected uint8 or uint16 "
                                        "(or give the full-scale value as levels=)")
    levels = float(levels)
    if not (np.isfinite(levels) and levels > 0):
        raise CalibrationImageError(f"levels must be a positive full-scale value, got {levels!r}")
    if arr.ndim == 3 and arr.shape[2] in (1, 2, 3, 4):
        channels = {1: 1, 2: 1, 3: 3, 4: 3}[arr.shape[2]]       # drop alpha (grey+alpha, colour+alpha)
        arr = arr[..., :channels]
        grey = arr[..., 0].astype(np.float64) if channels == 1 else arr.astype(np.float64).mean(axis=2)
    elif arr.ndim == 2:
        grey = arr.astype(np.float64)
    else:
        raise CalibrationImageError(f"unsupported image shape {arr.shape}: expected (H, W) grey, "
                                    "(H, W, 3) colour or (H, W, 4) colour with alpha")
    if grey.size == 0:
        raise CalibrationImageError(f"empty image of shape {arr.shape}")
    grey /= levels
    return grey


def read_image(path) -> np.ndarray:
    """Read a calibration photograph as a normalised grey image.

    Args:
        path: an 8- or 16-bit PNG or TIFF file, grey, RGB or RGBA.

    Returns:
        ``(H, W) float64`` grey image in [0, 1] (codes divided by 255 or 65535; colour -> mean of the channels,
        alpha dropped).

    Raises:
        CalibrationImageError: missing file, not a file, undecodable data, or an unsupported pixel type or
            shape; the message names ``path`` and says what was expected.
    """
    path = Path(path)
    if not path.exists():
        raise CalibrationImageError(f"{path}: no such file (expected {_EXPECTED})")
    if not path.is_file():
        raise CalibrationImageError(f"{path}: not a file (expected {_EXPECTED})")
    try:
        data = np.fromfile(str(path), dtype=np.uint8)        # = cv2.imread(IMREAD_UNCHANGED), for any path name
    except OSError as exc:
        raise CalibrationImageError(f"{path}: cannot be read ({exc.strerror or exc}); expected {_EXPECTED}") from exc
    with native_messages() as said:
        image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if image is None:
        why = f" ({'; '.join(said)})" if said else ""
        raise CalibrationImageError(f"{path}: not a readable image{why} (expected {_EXPECTED})")
    if image.dtype not in _FULL_SCALE:
        raise CalibrationImageError(f"{path}: unsupported pixel type {image.dtype} (expected {_EXPECTED})")
    try:
        return to_grey(image)
    except CalibrationImageError as exc:
        raise CalibrationImageError(f"{path}: {exc}") from exc
