"""A 4D light field as a folder of sub-aperture views, as camera arrays and the 4D light field benchmark distribute
them, and the benchmark's PFM maps.

A folder holds ``input_CamNNN.png`` (N x N views, row-major: left to right, then top to bottom; 8- or 16-bit, grey
or colour) and ``parameters.cfg`` (INI): ``[intrinsics]`` ``image_resolution_x_px``, ``image_resolution_y_px``,
``focal_length_mm``, ``sensor_size_mm``; ``[extrinsics]`` ``num_cams_x``, ``num_cams_y``, ``baseline_mm``,
``focus_distance_m``; ``[meta]`` ``disp_min``, ``disp_max`` (pixels per view step). A PFM file is one float32
channel (``Pf``), rows stored bottom to top, the scale's sign giving the byte order.
"""

from __future__ import annotations

import configparser
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from lftransfer.imageio_utils import ImageReadError, read_image, write_bytes, write_png16, write_text
from lftransfer.lightfield.disparity import shift_view

__all__ = ["ViewGrid", "ViewGridError", "read_pfm", "read_view_grid", "two_layer_grid", "write_pfm",
           "write_view_grid"]

class ViewGridError(ValueError):
    """A light field folder or PFM file that cannot be read; the message names the file and what was expected."""


@dataclass(frozen=True)
class ViewGrid:
    """A light field of sub-aperture views.

    Attributes:
        views: (T, S, H, W) float32 grey views in [0, 1] (T rows of S views).
        baseline_m: distance between neighbouring views, metres.
        focal_px: focal length, pixels (focal_length_mm x max(W, H) / sensor_size_mm).
        focus_m: the distance of zero disparity, metres.
        disp_min, disp_max: the scene's disparity range, pixels per view step.
    """

    views: np.ndarray
    baseline_m: float
    focal_px: float
    focus_m: float
    disp_min: float
    disp_max: float


def _number(cfg: configparser.ConfigParser, path: Path, section: str, key: str, kind=float):
    try:
        return kind(cfg.get(section, key))
    except (configparser.Error, ValueError) as exc:
        raise ViewGridError(f"{path}: [{section}] {key}: expected a number ({exc})") from None


def read_view_grid(folder: str | Path) -> ViewGrid:
    """Read a light field folder (module docstring).

    Raises:
        ViewGridError: a missing or malformed ``parameters.cfg``, missing or unreadable views, or views of another
            size than the parameters say; the message names the file.
    """
    folder = Path(folder)
    cfg_path = folder / "parameters.cfg"
    if not cfg_path.is_file():
        raise ViewGridError(f"{cfg_path}: no such file (a light field folder holds parameters.cfg and "
                            f"input_CamNNN.png views)")
    cfg = configparser.ConfigParser()
    try:
        cfg.read(cfg_path, encoding="utf-8")
    except configparser.Error as exc:
        raise ViewGridError(f"{cfg_path}: not an INI file ({exc})") from None
    w, h = (_number(cfg, cfg_path, "intrinsics", k, int) for k in ("image_resolution_x_px", "image_resolution_y_px"))
    nx, ny = (_number(cfg, cfg_path, "extrinsics", k, int) for k in ("num_cams_x", "num_cams_y"))
    focal_px = _number(cfg, cfg_path, "intrinsics", "focal_length_mm") * max(w, h) / _number(
        cfg, cfg_path, "intrinsics", "sensor_size_mm")
    views = np.empty((ny, nx, h, w), np.float32)
    for i in range(nx * ny):
        path = folder / f"input_Cam{i:03d}.png"
        if not path.is_file():
            raise ViewGridError(f"{path}: no such file ({nx} x {ny} views expected by {cfg_path.name})")
        try:
            view = read_image(path).astype(np.float32)
        except ImageReadError as exc:
            raise ViewGridError(str(exc)) from None
        if view.shape != (h, w):
            raise ViewGridError(f"{path}: {view.shape[1]} x {view.shape[0]} pixels, expected {w} x {h}")
        views[i // nx, i % nx] = view
    return ViewGrid(views, _number(cfg, cfg_path, "extrinsics", "baseline_mm") / 1000.0, focal_px,
                    _number(cfg, cfg_path, "extrinsics", "focus_distance_m"),
                    _number(cfg, cfg_path, "meta", "disp_min"), _number(cfg, cfg_path, "meta", "disp_max"))


def write_view_grid(folder: str | Path, grid: ViewGrid, *, focal_length_mm: float = 50.0) -> Path:
    """Write ``grid`` as a light field folder (16-bit grey views and ``parameters.cfg``), as the benchmark lays
    one out; returns the folder."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    t_n, s_n, h, w = grid.views.shape
    for i in range(t_n * s_n):
        view = np.round(np.clip(grid.views[i // s_n, i % s_n], 0.0, 1.0) * 65535).astype(np.uint16)
        write_png16(folder / f"input_Cam{i:03d}.png", view)
    sensor_mm = focal_length_mm * max(w, h) / grid.focal_px
    write_text(folder / "parameters.cfg", (
        f"[intrinsics]\nimage_resolution_x_px = {w}\nimage_resolution_y_px = {h}\n"
        f"focal_length_mm = {focal_length_mm!r}\nsensor_size_mm = {sensor_mm!r}\n\n"
        f"[extrinsics]\nnum_cams_x = {s_n}\nnum_cams_y = {t_n}\nbaseline_mm = {grid.baseline_m * 1000.0!r}\n"
        f"focus_distance_m = {grid.focus_m!r}\n\n[meta]\ndisp_min = {grid.disp_min!r}\n"
        f"disp_max = {grid.disp_max!r}\n"))
    return folder


def write_pfm(path: str | Path, image: np.ndarray) -> Path:
    """Write an (H, W) map as a one-channel little-endian PFM (rows bottom to top), atomically."""
    image = np.asarray(image, np.float32)
    if image.ndim != 2:
        raise ValueError(f"a PFM map is (H, W), got shape {image.shape}")
    h, w = image.shape
    header = f"Pf\n{w} {h}\n-1.0\n".encode("ascii")
    return write_bytes(path, header + np.ascontiguousarray(image[::-1]).astype("<f4").tobytes())


def read_pfm(path: str | Path) -> np.ndarray:
    """Read a one-channel PFM map: (H, W) float32, top row first.

    Raises:
        ViewGridError: not a one-channel PFM file, or one whose data is shorter than its header says.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ViewGridError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    parts = data.split(b"\n", 3)
    if len(parts) < 4 or parts[0].strip() != b"Pf":
        raise ViewGridError(f"{path}: not a one-channel PFM file (its first line must be 'Pf')")
    try:
        w, h = (int(v) for v in parts[1].split())
        scale = float(parts[2])
    except ValueError:
        raise ViewGridError(f"{path}: a PFM header gives the width and height, then the scale") from None
    if w <= 0 or h <= 0 or scale == 0:
        raise ViewGridError(f"{path}: a PFM map of {w} x {h} pixels with scale {scale} is not a map")
    body = parts[3]
    if len(body) < 4 * w * h:
        raise ViewGridError(f"{path}: holds {len(body)} bytes of data, a {w} x {h} map needs {4 * w * h}")
    values = np.frombuffer(body[:4 * w * h], dtype="<f4" if scale < 0 else ">f4").reshape(h, w)
    return values[::-1].astype(np.float32)


def two_layer_grid(n: int = 9, size: int = 512, *, front: float = 1.2, back: float = -0.5,
                   back_contrast: float = 1.0, seed: int = 0) -> tuple[ViewGrid, np.ndarray]:
    """A test light field of known disparity: ``n`` x ``n`` views of a textured square (disparity ``front``) in
    front of a textured plane (``back``), each view the layers shifted by minus their disparity times its offset
    from the centre view (bicubic; :mod:`lftransfer.lightfield.disparity`'s sign), a baseline of 1 cm, a focal
    length of 400 px and the focus plane at 1 m.

    Returns:
        (the grid, its centre view's true disparity (size, size) float32).
    """
    rng = np.random.default_rng(seed)

    def texture(contrast: float) -> np.ndarray:
        return 0.5 + contrast * cv2.GaussianBlur(rng.random((size, size)).astype(np.float32) - 0.5, (0, 0), 1.5)

    def shift(image: np.ndarray, d: float, ds: int, dt: int) -> np.ndarray:
        return shift_view(image, -d * ds, -d * dt)

    plane, square_tex = texture(back_contrast), texture(1.0)
    square = np.zeros((size, size), np.float32)
    square[size // 4:3 * size // 4, size // 3:2 * size // 3] = 1.0
    views = np.empty((n, n, size, size), np.float32)
    c = n // 2
    for t in range(n):
        for s in range(n):
            m = np.clip(shift(square, front, s - c, t - c), 0.0, 1.0)
            views[t, s] = m * shift(square_tex, front, s - c, t - c) + (1 - m) * shift(plane, back, s - c, t - c)
    lo, hi = min(front, back), max(front, back)
    grid = ViewGrid(np.clip(views, 0.0, 1.0), baseline_m=0.01, focal_px=400.0, focus_m=1.0,
                    disp_min=lo - 0.3 * (hi - lo), disp_max=hi + 0.3 * (hi - lo))
    return grid, np.where(square > 0, front, back).astype(np.float32)
