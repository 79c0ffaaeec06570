"""Phase-shifted fringes drawn by light fields on a plane in front of the array, and their decoding from the view
camera's images (structured light): the vocabulary the global pose (:mod:`lftransfer.calibration.pose`) and the
view camera's structured-light depth (:mod:`lftransfer.real_depth.structured_light`) share.

A sinusoid blurred by any point-symmetric kernel keeps its phase, so the phase the view camera sees at a point of
the plane is the plane coordinate drawn there, whatever the lenslets' blur.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from lftransfer.lightfield.lightfield import LightField
from lftransfer.optics import LensArray
from lftransfer.optics.geometry import backproject

__all__ = ["FRINGE_PERIOD_M", "FRINGE_SHIFTS", "BoardPattern", "FringeDecoding", "decode_fringes",
           "fringe_lightfields"]


@dataclass(frozen=True)
class BoardPattern:
    """A drawing plane in front of the array, in the model frame, with a grid of reference points on it (the inner
    corners of ``squares`` squares of ``square_m``).

    Attributes:
        centre: (3,) metres (z > 0: the real side).
        normal: (3,) unit normal, towards the array and the view camera.
        ex, ey: (3,) unit in-plane axes.
        squares: (columns, rows) of squares.
        square_m: square size, metres.
    """

    centre: np.ndarray
    normal: np.ndarray
    ex: np.ndarray
    ey: np.ndarray
    squares: tuple[int, int] = (6, 5)
    square_m: float = 0.045

    def outline(self, extent: tuple[float, float]) -> np.ndarray:
        """(4, 3) model-frame corners of a rectangle of ``extent`` (width along ``ex``, height along ``ey``,
        metres) centred on the board."""
        w, h = float(extent[0]) / 2, float(extent[1]) / 2
        return np.array([self.centre + sx * w * self.ex + sy * h * self.ey for sx in (-1, 1) for sy in (-1, 1)])

    def corners(self) -> np.ndarray:
        """(N, 3) model-frame positions of the inner corners, row-major."""
        b = self.board_2d()
        return self.centre + b[:, :1] * self.ex + b[:, 1:2] * self.ey

    def board_2d(self) -> np.ndarray:
        """(N, 3) the same corners in the board's own plane (z = 0), for ``cv2.solvePnP``."""
        cols, rows = self.squares
        i, j = np.meshgrid(np.arange(1, cols) - cols / 2, np.arange(1, rows) - rows / 2)
        return np.stack([i.ravel(), j.ravel(), np.zeros(i.size)], 1) * self.square_m


FRINGE_PERIOD_M = 0.06    # metres on the board: blurred by a 25 mm aperture, a 60 mm sinusoid keeps ~3/4 of its contrast
FRINGE_SHIFTS = 4         # phase steps per direction


def fringe_lightfields(array: LensArray, U: int, V: int, board: BoardPattern, extent: tuple[float, float],
                       radiance: float, period_m: float = FRINGE_PERIOD_M, shifts: int = FRINGE_SHIFTS,
                       supersample: int = 4) -> list[LightField]:
    """Light fields whose rays draw phase-shifted sinusoidal fringes on the board plane (structured light).

    Sample (k, d) stands for the rays leaving lenslet k's centre within its angular cell around +d; where they meet
    the plane inside the ``extent`` rectangle it carries ``radiance (1 + cos(2 pi s / T + 2 pi j / shifts)) / 2``
    averaged over ``supersample`` x ``supersample`` rays across the cell, with s the board coordinate (metres from
    ``board.centre`` along ``board.ex``, then along ``board.ey``) and T the period. A sinusoid blurred by any
    point-symmetric kernel (a lenslet aperture seen obliquely, a cell's spread of directions) keeps its phase and
    loses only contrast, so the phase that the view camera sees at a point of the board is the board coordinate
    drawn there, whatever the blur; the board's albedo and the light's fall-off cancel in the phase.

    Args:
        array: the lens array (model frame).
        U, V: angular samples.
        board: the drawing plane and its axes.
        extent: (width, height) metres of the lit rectangle centred on ``board.centre``.
        radiance: peak radiance.
        period_m: fringe period T, metres.
        shifts: phase steps per direction.
        supersample: rays per cell and axis.

    Returns:
        ``2 * shifts`` LightFields (K, V, U, 3) float32: the fringes along ``ex`` at each phase step, then along
        ``ey``.
    """
    lf = LightField.zeros(array, U, V)
    uu, vv = np.meshgrid(lf.u, lf.v)
    du, dv = 2.0 * array.half_width / U, 2.0 * array.half_width / V
    c = array.centres3d[:, None, None, :]                                 # (K, 1, 1, 3)
    phases = 2 * np.pi * np.arange(shifts) / shifts
    acc = np.zeros((2, shifts, array.K, V, U))
    steps = (np.arange(supersample) + 0.5) / supersample - 0.5
    for sv in steps:
        for su in steps:
            d = np.stack([uu + su * du, vv + sv * dv, np.ones_like(uu)], axis=-1)
            d /= np.linalg.norm(d, axis=-1, keepdims=True)
            with np.errstate(divide="ignore", invalid="ignore"):
                t = ((board.centre - c) @ board.normal) / (d @ board.normal)
            rel = c + t[..., None] * d[None] - board.centre
            a, b = rel @ board.ex, rel @ board.ey                          # (K, V, U) metres
            hit = (t > 0) & (np.abs(a) < extent[0] / 2) & (np.abs(b) < extent[1] / 2)
            for axis, coord in enumerate((a, b)):
                wave = 2 * np.pi * np.where(hit, coord, 0.0)[None] / period_m + phases[:, None, None, None]
                acc[axis] += hit * 0.5 * (1.0 + np.cos(wave))
    acc *= radiance * lf.mask()[None, None, None] / supersample ** 2
    out = []
    for axis in range(2):
        for j in range(shifts):
            f = LightField.zeros(array, U, V)
            f.data[...] = acc[axis, j][..., None]
            out.append(f)
    return out


@dataclass(frozen=True)
class FringeDecoding:
    """What the view camera saw of the fringes: each pixel's board coordinates on the drawing plane.

    Attributes:
        coords: (H, W, 2) float64 board coordinates (metres along ``ex``, ``ey``), unwrapped; NaN where invalid.
        contrast: (H, W, 2) float32 fringe modulation over mean (1: full contrast).
        valid: (H, W) bool, pixels whose two phases are trusted.
        wrapped: (H, W) float32 cos of the phase along ``ex`` (for the report).
    """

    coords: np.ndarray
    contrast: np.ndarray
    valid: np.ndarray
    wrapped: np.ndarray


def decode_fringes(images: list[np.ndarray], board: BoardPattern, extent: tuple[float, float], view,
                   plane_to_world: Callable[[np.ndarray], np.ndarray] | None = None, *,
                   period_m: float = FRINGE_PERIOD_M, margin_m: float = 0.0254,
                   min_contrast: float = 0.25) -> FringeDecoding:
    """Board coordinates of every view camera pixel from the phase-shifted fringes (see :func:`fringe_lightfields`).

    The phase of each direction is ``atan2(-sum I_j sin phi_j, sum I_j cos phi_j)``; the period's index comes from
    the coordinates predicted on the expected board plane (good to well under half a period, 30 mm). Pixels within
    ``margin_m`` of the lit rectangle's edge (where the blur mixes in the unlit border and bends the phase), dark
    pixels and pixels of low contrast are invalid.

    Args:
        images: ``2 * shifts`` (H, W, 3) view camera images (linear radiance), in the order of
            :func:`fringe_lightfields`.
        board, extent: the drawing plane and the lit rectangle.
        view: ``ViewConfig``.
        plane_to_world: where the drawing plane is predicted (model frame -> world); identity if None.
        period_m: fringe period, metres.
        margin_m: excluded border, metres (about a lenslet pitch: the blur's reach).
        min_contrast: smallest modulation / mean that is trusted.

    Returns:
        FringeDecoding.
    """
    shifts = len(images) // 2
    phases = 2 * np.pi * np.arange(shifts) / shifts
    grey = np.stack([np.asarray(im, np.float64).mean(axis=2) for im in images])   # (2 shifts, H, W)
    h, w = grey.shape[1:]
    to_world = plane_to_world or (lambda X: X)
    origin = to_world(board.centre[None])[0]
    ex = to_world((board.centre + board.ex)[None])[0] - origin
    ey = to_world((board.centre + board.ey)[None])[0] - origin
    normal = np.cross(ex, ey)
    ys, xs = np.mgrid[0:h, 0:w]
    px = np.stack([xs.ravel(), ys.ravel()], 1).astype(np.float64)
    X = backproject(view, px, origin, normal / np.linalg.norm(normal))
    predicted = [((X - origin) @ e / (e @ e)).reshape(h, w) for e in (ex, ey)]
    coords, contrast = np.full((h, w, 2), np.nan), np.zeros((h, w, 2), np.float32)
    mean_all = grey.mean(axis=0)
    lit = mean_all > 0.05 * np.percentile(mean_all, 99.5)
    valid = lit.copy()
    wrapped = np.zeros((h, w), np.float32)
    for axis in range(2):
        stack = grey[axis * shifts:(axis + 1) * shifts]
        cs = np.tensordot(np.cos(phases), stack, 1)
        sn = np.tensordot(np.sin(phases), stack, 1)
        mean = stack.mean(axis=0)
        with np.errstate(divide="ignore", invalid="ignore"):
            contrast[..., axis] = (2.0 / shifts) * np.hypot(cs, sn) / mean
        phase = np.arctan2(-sn, cs)
        s = phase * period_m / (2 * np.pi)
        coords[..., axis] = s + np.round((predicted[axis] - s) / period_m) * period_m
        half = extent[axis] / 2 - margin_m
        valid &= np.nan_to_num(contrast[..., axis]) >= min_contrast
        valid &= np.abs(np.nan_to_num(coords[..., axis], nan=np.inf)) < half
        if axis == 0:
            wrapped = np.where(lit, np.cos(phase), 0.0).astype(np.float32)
    coords[~valid] = np.nan
    return FringeDecoding(coords, contrast, valid, wrapped)
