"""The lattice model and its fit (step 4 of :mod:`lftransfer.calibration.lenslets`): homography + radial distortion.

``p = c + (q - c) (1 + k1 rho^2 + k2 rho^4)``, ``q = H (u, v, 1)``, ``rho = |q - c| / s``: ideal lattice
coordinates ``(u, v)`` (unit pitch) to pixels, fitted by least squares; the radial terms kept only where
significant.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import cv2
import numpy as np
from scipy.optimize import least_squares

from lftransfer.calibration.lenslets.common import NoSpotsError, _apply

_CENTRE_PRIOR_PX = 2.0     # prior on the distortion centre: residual (px) per half-diagonal off the image centre
_F_RADIAL = 10.0           # radial terms kept if F of (homography vs homography + radial) exceeds this


class _Model(NamedTuple):
    """Lattice model: ideal ``(u, v)`` -> ``h`` -> undistorted pixels -> radial distortion about ``centre``."""

    h: np.ndarray                # (3, 3)
    k: np.ndarray                # (2,) k1, k2
    centre: np.ndarray           # (2,) pixels
    scale: float                 # pixels; rho = |q - centre| / scale


def _distort(q: np.ndarray, centre: np.ndarray, scale: float, k: np.ndarray) -> np.ndarray:
    """``(N, 2)`` undistorted pixels -> distorted: ``c + (q - c) (1 + k1 rho^2 + k2 rho^4)``."""
    d = (q - centre) / scale
    r2 = np.sum(d * d, axis=1, keepdims=True)
    return centre + scale * d * (1.0 + k[0] * r2 + k[1] * r2 * r2)


def _undistort(p: np.ndarray, centre: np.ndarray, scale: float, k: np.ndarray, iterations: int = 50
               ) -> np.ndarray:
    """Inverse of :func:`_distort` (fixed-point iteration; a few percent of distortion converge fast)."""
    if not np.any(k):
        return np.array(p, dtype=np.float64)
    d = (p - centre) / scale
    u = d.copy()
    for _ in range(iterations):
        r2 = np.sum(u * u, axis=1, keepdims=True)
        new = d / np.maximum(1.0 + k[0] * r2 + k[1] * r2 * r2, 0.1)
        if np.max(np.abs(new - u), initial=0.0) < 1e-13:
            u = new
            break
        u = new
    return centre + scale * u


def _model_apply(m: _Model, uv: np.ndarray) -> np.ndarray:
    return _distort(_apply(m.h, uv), m.centre, m.scale, m.k)


def _model_inverse(m: _Model, xy: np.ndarray) -> np.ndarray:
    return _apply(np.linalg.inv(m.h), _undistort(xy, m.centre, m.scale, m.k))


def _homography(nodes: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Least-squares homography ideal ``(N, 2)`` -> pixels ``(N, 2)``, normalised to ``h[2, 2] = 1``."""
    if len(nodes) < 4 or len(np.unique(nodes[:, 0])) < 2 or len(np.unique(nodes[:, 1])) < 2:
        raise NoSpotsError(f"the {len(nodes)} detections on the lattice do not span two rows and columns; "
                           "cannot fit a lattice")
    h, _ = cv2.findHomography(nodes.astype(np.float64), points.astype(np.float64), 0)
    if h is None or not np.all(np.isfinite(h)) or abs(np.linalg.det(h)) < 1e-12:
        raise NoSpotsError(f"could not fit a lattice homography to {len(nodes)} detections")
    return h / h[2, 2]


def _fit_model(ideal: np.ndarray, points: np.ndarray, shape: tuple[int, int], radial: bool = True
               ) -> tuple[_Model, float, float]:
    """Lattice model (least squares) through ``points`` at ideal coordinates ``ideal``.

    The homography is OpenCV's least-squares one; with ``radial``, homography, ``k1``, ``k2`` and the
    distortion centre are then refined together (Levenberg-Marquardt, in coordinates normalised by the
    image's half-diagonal and the lattice's spread), with a weak prior holding the centre near the image
    centre. The radial terms are kept only if significant (see the module's docstring).

    Returns:
        The model, its RMS residual and the homography's alone, pixels.
    """
    h_img, w_img = shape
    c0 = np.array([(w_img - 1) / 2.0, (h_img - 1) / 2.0])
    scale = max(0.5 * math.hypot(h_img - 1, w_img - 1), 1.0)
    hom = _homography(ideal, points)
    res_h = points - _apply(hom, ideal)
    rss_h = float(np.sum(res_h ** 2))
    n = len(points)
    plain = _Model(hom, np.zeros(2), c0, scale)
    rms_h = math.sqrt(rss_h / n)
    spans = min(len(np.unique(np.round(ideal[:, 0], 6))), len(np.unique(np.round(ideal[:, 1], 6))))
    if not radial or n < 16 or spans < 3 or rss_h <= 0:
        return plain, rms_h, rms_h
    mu = ideal.mean(axis=0)
    su = float(np.sqrt(np.mean(np.sum((ideal - mu) ** 2, axis=1)))) or 1.0
    uvn = (ideal - mu) / su
    qn = (points - c0) / scale
    t_uv = np.array([[1 / su, 0, -mu[0] / su], [0, 1 / su, -mu[1] / su], [0, 0, 1.0]])
    t_px = np.array([[scale, 0, c0[0]], [0, scale, c0[1]], [0, 0, 1.0]])
    hn = np.linalg.inv(t_px) @ hom @ np.linalg.inv(t_uv)
    hn /= hn[2, 2]

    def residual(x):
        hh = np.append(x[:8], 1.0).reshape(3, 3)
        pred = _distort(_apply(hh, uvn), x[10:12], 1.0, x[8:10])
        return np.concatenate([((pred - qn) * scale).ravel(), _CENTRE_PRIOR_PX * x[10:12]])

    x0 = np.concatenate([hn.ravel()[:8], np.zeros(4)])
    try:
        sol = least_squares(residual, x0, method="lm", x_scale="jac", xtol=1e-12, ftol=1e-12)
    except (ValueError, np.linalg.LinAlgError):
        return plain, rms_h, rms_h
    hh = t_px @ np.append(sol.x[:8], 1.0).reshape(3, 3) @ t_uv
    model = _Model(hh / hh[2, 2], sol.x[8:10].copy(), c0 + scale * sol.x[10:12], scale)
    rss_r = float(np.sum((points - _model_apply(model, ideal)) ** 2))
    dof = 2 * n - 12
    f_stat = (rss_h - rss_r) / 4.0 / max(rss_r / dof, 1e-300)
    if not (np.all(np.isfinite(model.h)) and f_stat > _F_RADIAL and rss_r < 0.98 ** 2 * rss_h):
        return plain, rms_h, rms_h
    return model, math.sqrt(rss_r / n), rms_h


def _pitch_rotation(model: _Model, shape: tuple[int, int]) -> tuple[float, float]:
    """Row spacing (pixels) and row direction (degrees counter-clockwise on screen) at the image centre."""
    centre = np.array([[(shape[1] - 1) / 2.0, (shape[0] - 1) / 2.0]])
    uv = _model_inverse(model, centre)[0]
    eps = 1e-4
    d = (_model_apply(model, (uv + [eps, 0.0])[None]) - _model_apply(model, (uv - [eps, 0.0])[None]))[0] / (2 * eps)
    return float(math.hypot(d[0], d[1])), float(math.degrees(math.atan2(-d[1], d[0])))
