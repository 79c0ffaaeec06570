"""Image files: linear float images as EXR (through Mitsuba's Bitmap), display images as sRGB PNG.

Every write goes to a temporary file in the destination folder and is renamed into place, so an interrupted
run never leaves a half-written file and never destroys an earlier complete one. Image decoders that print on
the process's standard error (libpng, OpenCV) are read through :func:`native_messages`, so their words end up in
the caller's error message instead of the terminal.
"""

from __future__ import annotations

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
