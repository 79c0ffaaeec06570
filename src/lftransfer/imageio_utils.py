"""Image files: linear float images as EXR (through Mitsuba's Bitmap), display images as sRGB PNG, device codes as
16-bit PNG, and photographs read back as normalised grey images (:func:`read_image`, :func:`to_grey`: an 8/16-bit
PNG or TIFF file and an array already held give the same ``(H, W) float64`` in [0, 1], colour averaged, alpha
dropped).

Every write goes to a temporary file in the destination folder and is renamed into place, so an interrupted
run never leaves a half-written file and never destroys an earlier complete one. Image decoders that print on
the process's standard error (libpng, OpenCV) are read through :func:`native_messages`, so their words end up in
the caller's error message instead of the terminal.
"""

from __future__ import annotations

import functools
import json
import math
import os
import re
import sys
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np


def _atomic_target(path: Path):
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    os.chmod(tmp, 0o644)                  # mkstemp makes files private; outputs are for reading
    return Path(tmp)


def write_text(path: str | Path, text: str) -> Path:
    """Write a text file atomically (temporary file in the same folder, then ``os.replace``), readable by all.

    Args:
        path: destination; its folder is created if missing.
        text: the contents (UTF-8, ``\\n`` line ends).

    Returns:
        The path.
    """
    return write_bytes(path, text.encode("utf-8"))


def write_bytes(path: str | Path, data: bytes) -> Path:
    """Write a binary file (an encoded PNG, UTF-8 text, ...) atomically: a temporary file in the same folder, then
    ``os.replace``."""
    path = Path(path)
    tmp = _atomic_target(path)
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def write_npz(path: str | Path, **arrays: np.ndarray) -> Path:
    """Write named arrays as an uncompressed ``.npz`` file, atomically (:func:`write_bytes`)."""
    import io

    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    return write_bytes(path, buffer.getvalue())


def strict_json(value):
    """``value`` as plain, strict JSON data: numpy scalars and arrays as Python numbers and lists, tuples as
    lists, paths as strings, and every non-finite float (NaN, infinity) as None, which JSON can hold (``NaN`` is
    not JSON)."""
    if isinstance(value, dict):
        return {str(k): strict_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [strict_json(v) for v in value]
    if isinstance(value, np.ndarray):
        return strict_json(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, Path):
        return str(value)
    return value


def write_json(path: str | Path, data, indent: int = 2) -> Path:
    """Write strict JSON (:func:`strict_json`: no NaN or infinity) atomically (:func:`write_text`)."""
    return write_text(path, json.dumps(strict_json(data), indent=indent, allow_nan=False) + "\n")


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """sRGB transfer function of linear values in [0, 1] (values outside are clipped)."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def to_display(rgb: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """(H, W, 3) linear radiance times ``scale`` -> (H, W, 3) uint8 sRGB."""
    return np.round(linear_to_srgb(np.asarray(rgb, np.float64) * scale) * 255).astype(np.uint8)


PREVIEW_LEVELS = 65536
"""Linear levels of :func:`to_preview`'s table over [0, 1]."""


@functools.cache
def _preview_table() -> np.ndarray:
    """(:data:`PREVIEW_LEVELS`,) uint8: :func:`to_display` of each level, made once."""
    return to_display(np.linspace(0.0, 1.0, PREVIEW_LEVELS))


def to_preview(rgb: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """(H, W, 3) linear radiance times ``scale`` -> (H, W, 3) uint8 sRGB, for a live page's frames: the sRGB curve
    looked up in a table of :data:`PREVIEW_LEVELS` linear levels instead of computed per pixel (a 1024 x 768 view in
    6 ms instead of 33 on this project's 2-core machine). It approximates :func:`to_display`: within one code, and
    equal to it for all but values within a table step of a rounding edge. Negative values and NaN show black, as
    :func:`to_display` shows negative ones. Written images use :func:`to_display`."""
    v = np.multiply(rgb, np.float32(scale * (PREVIEW_LEVELS - 1)), dtype=np.float32)
    np.fmax(v, 0.0, out=v)                      # NaN -> 0
    np.fmin(v, PREVIEW_LEVELS - 1, out=v)
    v += 0.5
    return _preview_table()[v.astype(np.uint16)]


def write_png(path: str | Path, image: np.ndarray) -> Path:
    """Write an 8-bit (H, W, 3) image, or a float image in [0, 1] as sRGB-encoded linear values, atomically."""
    import imageio.v3 as iio

    path = Path(path)
    img = np.asarray(image)
    if img.dtype != np.uint8:
        img = to_display(img)
    tmp = _atomic_target(path)
    try:
        iio.imwrite(tmp, img, extension=".png")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def write_png16(path: str | Path, image: np.ndarray) -> Path:
    """Write a uint16 image, (H, W) grey or (H, W, 3) RGB, as a 16-bit PNG (device codes, a light field's views),
    atomically."""
    import cv2

    image = np.asarray(image)
    if image.dtype != np.uint16 or image.ndim not in (2, 3):
        raise ValueError(f"a 16-bit PNG holds an (H, W) or (H, W, 3) uint16 image, got {image.dtype} {image.shape}")
    ok, data = cv2.imencode(".png", np.ascontiguousarray(image[..., ::-1] if image.ndim == 3 else image))
    if not ok:                                          # OpenCV writes BGR
        raise OSError(f"{path}: the PNG encoder refused a {image.shape} image")
    return write_bytes(path, data.tobytes())


def write_exr(path: str | Path, image: np.ndarray) -> Path:
    """Write a float32 (H, W, C) linear image as OpenEXR, atomically."""
    from lftransfer.backend import mitsuba

    mi = mitsuba()
    path = Path(path)
    tmp = _atomic_target(path)
    try:
        mi.Bitmap(np.ascontiguousarray(image, dtype=np.float32)).write(str(tmp))
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def write_figure(path: str | Path, figure, *, dpi: int = 120) -> Path:
    """Write a matplotlib figure (the format from the suffix: .png, .svg, .pdf), atomically, and close it."""
    import matplotlib.pyplot as plt

    path = Path(path)
    tmp = _atomic_target(path)
    try:
        figure.savefig(tmp, dpi=dpi, format=path.suffix.lstrip(".") or "png", bbox_inches="tight")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
        plt.close(figure)
    return path


def write_video(path: str | Path, frames: Iterable[np.ndarray], fps: float) -> Path:
    """Write 8-bit (H, W, 3) frames as an H.264 MP4 (imageio's ffmpeg), atomically.

    Frames are padded with black to even sizes (the yuv420p pixel format needs them); every frame must have the
    first one's size.
    """
    import imageio.v2 as iio2

    path = Path(path)
    tmp = _atomic_target(path)
    try:
        writer = iio2.get_writer(tmp, format="FFMPEG", mode="I", fps=float(fps), codec="libx264",
                                 pixelformat="yuv420p", macro_block_size=1, quality=8,
                                 ffmpeg_log_level="error")
        try:
            size = None
            for frame in frames:
                img = np.asarray(frame, np.uint8)[..., :3]
                if size is None:
                    size = img.shape
                if img.shape != size:
                    raise ValueError(f"{path}: frame of shape {img.shape}, the first was {size}")
                writer.append_data(np.pad(img, ((0, img.shape[0] % 2), (0, img.shape[1] % 2), (0, 0))))
            if size is None:
                raise ValueError(f"{path}: no frames to write")
        finally:
            writer.close()
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def read_exr(path: str | Path) -> np.ndarray:
    """Read an EXR written by :func:`write_exr` as float32 (H, W, C)."""
    from lftransfer.backend import mitsuba

    mi = mitsuba()
    return np.array(mi.Bitmap(str(path)), dtype=np.float32)


_OPENCV_LOG = re.compile(r"^\[\s*\w+:[^\]]*\]\s*(?:global\s+)?\S+\s+\S+\s+(.*)$")


@contextmanager
def native_messages() -> Iterator[list[str]]:
    """Capture what native code (libpng, libtiff, OpenCV's log) writes to file descriptor 2 during the block.

    Yields:
        A list that, once the block ends, holds the captured lines, cleaned (``"libpng error: bad adaptive
        filter value"``, ``"PNG input buffer is incomplete"``); nothing reaches the terminal.
    """
    lines: list[str] = []
    try:
        sys.stderr.flush()
    except (AttributeError, ValueError):  # pragma: no cover - a closed or replaced stream
        pass
    try:
        saved = os.dup(2)
    except OSError:  # pragma: no cover - no descriptor 2: nothing to capture
        yield lines
        return
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield lines
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            for raw in sink.read().decode("utf-8", "replace").splitlines():
                m = _OPENCV_LOG.match(raw.strip())
                text = (m.group(1) if m else raw).strip()
                if text:
                    lines.append(text)


_EXPECTED = "an 8- or 16-bit PNG or TIFF image (grey, RGB or RGBA)"
_FULL_SCALE = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}


class ImageReadError(ValueError):
    """An image file (a calibration photograph, a light field's view) could not be read or has an unsupported
    format; the message names the file if any."""


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
        ImageReadError: unsupported dtype or shape, empty image, or a non-positive ``levels``.
    """
    arr = np.asarray(image)
    if arr.dtype.kind not in "uif":
        raise ImageReadError(f"unsupported pixel type {arr.dtype}: expected uint8, uint16 or float values")
    if levels is None:
        if arr.dtype.kind == "f":
            levels = 1.0
        elif arr.dtype in _FULL_SCALE:
            levels = _FULL_SCALE[arr.dtype]
        else:
            raise ImageReadError(f"unsupported pixel type {arr.dtype}: expected uint8 or uint16 "
                                        "(or give the full-scale value as levels=)")
    levels = float(levels)
    if not (np.isfinite(levels) and levels > 0):
        raise ImageReadError(f"levels must be a positive full-scale value, got {levels!r}")
    if arr.ndim == 3 and arr.shape[2] in (1, 2, 3, 4):
        channels = {1: 1, 2: 1, 3: 3, 4: 3}[arr.shape[2]]       # drop alpha (grey+alpha, colour+alpha)
        arr = arr[..., :channels]
        grey = arr[..., 0].astype(np.float64) if channels == 1 else arr.astype(np.float64).mean(axis=2)
    elif arr.ndim == 2:
        grey = arr.astype(np.float64)
    else:
        raise ImageReadError(f"unsupported image shape {arr.shape}: expected (H, W) grey, "
                                    "(H, W, 3) colour or (H, W, 4) colour with alpha")
    if grey.size == 0:
        raise ImageReadError(f"empty image of shape {arr.shape}")
    grey /= levels
    return grey


def read_image(path) -> np.ndarray:
    """Read a photograph (a calibration step's, a light field's view) as a normalised grey image.

    Args:
        path: an 8- or 16-bit PNG or TIFF file, grey, RGB or RGBA.

    Returns:
        ``(H, W) float64`` grey image in [0, 1] (codes divided by 255 or 65535; colour -> mean of the channels,
        alpha dropped).

    Raises:
        ImageReadError: missing file, not a file, undecodable data, or an unsupported pixel type or
            shape; the message names ``path`` and says what was expected.
    """
    import cv2

    path = Path(path)
    if not path.exists():
        raise ImageReadError(f"{path}: no such file (expected {_EXPECTED})")
    if not path.is_file():
        raise ImageReadError(f"{path}: not a file (expected {_EXPECTED})")
    try:
        data = np.fromfile(str(path), dtype=np.uint8)        # = cv2.imread(IMREAD_UNCHANGED), for any path name
    except OSError as exc:
        raise ImageReadError(f"{path}: cannot be read ({exc.strerror or exc}); expected {_EXPECTED}") from exc
    with native_messages() as said:
        image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if image is None:
        why = f" ({'; '.join(said)})" if said else ""
        raise ImageReadError(f"{path}: not a readable image{why} (expected {_EXPECTED})")
    if image.dtype not in _FULL_SCALE:
        raise ImageReadError(f"{path}: unsupported pixel type {image.dtype} (expected {_EXPECTED})")
    try:
        return to_grey(image)
    except ImageReadError as exc:
        raise ImageReadError(f"{path}: {exc}") from exc
