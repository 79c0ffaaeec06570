"""Disparity of a 4D light field given as a grid of sub-aperture views: a plane sweep over a cost volume that is
occlusion-aware and filtered edge-aware (``lft depth``).

A light field from a camera array or a lenslet camera's decoding is an ``(T, S, H, W)`` grid of views: ``S``
across (left to right), ``T`` down (top to bottom), each ``H x W`` pixels. A point of **disparity** ``d`` (pixels
per view step) seen at pixel ``p`` of the centre view ``(s_c, t_c)`` is seen at ``p - d (s - s_c, t - t_c)`` in
view ``(s, t)``; ``d = 0`` on the focus plane and ``d > 0`` nearer than it, so that the depth is
``Z = 1 / (d / (B f) + 1 / Z0)`` (baseline ``B`` in metres, focal length ``f`` in pixels, focus distance ``Z0``),
the 4D light field benchmark's convention (Honauer et al., ACCV 2016: its ``disp2depth``).

For each candidate disparity every view is shifted back onto the centre view (:func:`cv2.warpAffine`, bilinear)
and compared with it. The cost of a pixel is the mean absolute difference over the **best of four half-grids** of
views (left, right, above, below the centre): a point hidden from the views on one side by a nearer object still
matches in the others (occlusion-aware matching, instead of averaging over views that see the occluder). Each candidate's cost slice is then filtered with a
**guided filter** guided by the centre view (He et al., 2013, from box filters: edges of the cost follow edges of
the image, instead of bleeding a window's width past them). The disparity is the candidate of least cost, refined
by a parabola through its neighbours; its confidence is how much worse the second-best separated candidate is.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["BADPIX_THRESHOLD", "BORDER_PX", "Disparity", "disparity_to_depth", "estimate_disparity", "guided_filter",
           "score_disparity", "shift_view", "view_groups"]

BADPIX_THRESHOLD = 0.07
"""The benchmark's BadPix threshold: a pixel whose disparity is off by more than this many pixels per view step."""
BORDER_PX = 15
"""Pixels left out at each side of the image when scoring (the benchmark's boundary offset)."""


@dataclass(frozen=True)
class Disparity:
    """A light field's estimated disparity.

    Attributes:
        disparity: (H, W) float32, pixels per view step (module docstring's sign).
        confidence: (H, W) float32 in [0, 1]: 0 where the cost has no clear minimum (no texture), towards 1 where
            it has one.
        candidates: (D,) float32 the disparities tried.
    """

    disparity: np.ndarray
    confidence: np.ndarray
    candidates: np.ndarray


def guided_filter(guide: np.ndarray, src: np.ndarray, radius: int, eps: float) -> np.ndarray:
    """He et al.'s guided filter of ``src`` (H, W) by a grey ``guide`` (H, W): an edge-aware smoothing whose output
    is locally linear in the guide over (2 ``radius`` + 1)^2 windows; ``eps`` (in the guide's units squared) sets
    how strong an edge of the guide must be to be kept. Returns (H, W) float32."""
    size = (2 * radius + 1, 2 * radius + 1)

    def mean(x: np.ndarray) -> np.ndarray:
        return cv2.boxFilter(x, cv2.CV_32F, size, borderType=cv2.BORDER_REFLECT)

    g, p = guide.astype(np.float32), src.astype(np.float32)
    mean_g, mean_p = mean(g), mean(p)
    var_g = mean(g * g) - mean_g * mean_g
    a = (mean(g * p) - mean_g * mean_p) / (var_g + np.float32(eps))
    b = mean_p - a * mean_g
    return mean(a) * g + mean(b)


def shift_view(view: np.ndarray, dx: float, dy: float) -> np.ndarray:
    """``view`` translated by (dx, dy) pixels, bicubic (bilinear blurs a fractional shift enough to bias the cost
    towards whole-pixel shifts), the border repeated."""
    m = np.float32([[1.0, 0.0, dx], [0.0, 1.0, dy]])
    return cv2.warpAffine(view, m, (view.shape[1], view.shape[0]), flags=cv2.INTER_CUBIC,
                          borderMode=cv2.BORDER_REPLICATE)


def _cost_slice(views: np.ndarray, centre: np.ndarray, offsets: np.ndarray, d: float, groups: np.ndarray,
                radius: int, eps: float | None) -> np.ndarray:
    """The filtered cost (H, W) of disparity ``d``: each view shifted back by ``d`` times its offset, the mean
    absolute difference to the centre view over each group of views (``groups``: (G, V) bool), the least of the
    groups' means, guided-filtered by the centre view."""
    diffs = np.empty((len(views), *centre.shape), np.float32)
    for k, (view, (ds, dt)) in enumerate(zip(views, offsets)):
        diffs[k] = np.abs(shift_view(view, d * ds, d * dt) - centre)
    means = np.stack([diffs[g].mean(axis=0) for g in groups]).min(axis=0)
    if eps is None:                         # the control: a plain window, blind to the image's edges
        return cv2.boxFilter(means, cv2.CV_32F, (2 * radius + 1, 2 * radius + 1), borderType=cv2.BORDER_REFLECT)
    return guided_filter(centre, means, radius, eps)


def view_groups(offsets: np.ndarray, occlusion_aware: bool = True) -> np.ndarray:
    """(G, V) bool: the groups of views a pixel's cost is the best of. Occlusion-aware: the four half-grids (the
    views left of the centre, right of it, above and below, each with the centre's row or column), so that a point
    that a nearer object hides from the views on one side is matched in the others; else one group of every
    view."""
    ds, dt = offsets[:, 0], offsets[:, 1]
    if not occlusion_aware:
        return np.ones((1, len(offsets)), bool)
    return np.stack([ds <= 0, ds >= 0, dt <= 0, dt >= 0])


def estimate_disparity(views: np.ndarray, *, disp_min: float, disp_max: float, steps: int = 64,
                       radius: int = 4, eps: float | None = 1e-4, occlusion_aware: bool = True) -> Disparity:
    """The disparity of the centre view of a grid of views (module docstring).

    Args:
        views: (T, S, H, W) grey views in [0, 1] (T and S odd: the centre view is ``(T // 2, S // 2)``).
        disp_min, disp_max: the range of disparities to try, pixels per view step.
        steps: candidates, evenly spaced over the range.
        radius: the guided filter's window radius, pixels.
        eps: the guided filter's regularisation (grey levels squared); None: a plain box filter of the same window
            instead (the control that shows a window's bleed past the edges).
        occlusion_aware: a pixel's cost is the best of four half-grids of views (:func:`view_groups`); False:
            the mean over every view (the control that shows the bleed at occluding edges).

    Returns:
        :class:`Disparity`.
    """
    views = np.asarray(views, np.float32)
    if views.ndim != 4 or views.shape[0] % 2 == 0 or views.shape[1] % 2 == 0:
        raise ValueError(f"views must be (T, S, H, W) with T and S odd, got shape {views.shape}")
    if not (np.isfinite(disp_min) and np.isfinite(disp_max) and disp_max > disp_min) or steps < 3:
        raise ValueError(f"need disp_min < disp_max and steps >= 3, got {disp_min}, {disp_max}, {steps}")
    t_n, s_n, h, w = views.shape
    tc, sc = t_n // 2, s_n // 2
    centre = views[tc, sc]
    t, s = np.meshgrid(np.arange(t_n) - tc, np.arange(s_n) - sc, indexing="ij")
    offsets = np.stack([s.ravel(), t.ravel()], 1).astype(np.float32)              # (V, 2): (ds, dt)
    flat = views.reshape(-1, h, w)
    groups = view_groups(offsets, occlusion_aware)
    candidates = np.linspace(disp_min, disp_max, steps, dtype=np.float32)
    cost = np.stack([_cost_slice(flat, centre, offsets, float(d), groups, radius, eps) for d in candidates])
    return _winner(cost, candidates)


def _winner(cost: np.ndarray, candidates: np.ndarray) -> Disparity:
    """The least-cost candidate per pixel of a (D, H, W) cost volume, refined by a parabola through its
    neighbours, and its confidence: 1 - best / (the best cost at least 3 candidates away)."""
    n = len(candidates)
    best = np.argmin(cost, axis=0)
    i = np.clip(best, 1, n - 2)
    c0 = np.take_along_axis(cost, (i - 1)[None], 0)[0]
    c1 = np.take_along_axis(cost, i[None], 0)[0]
    c2 = np.take_along_axis(cost, (i + 1)[None], 0)[0]
    curvature = c0 - 2 * c1 + c2
    with np.errstate(divide="ignore", invalid="ignore"):
        offset = np.where(curvature > 0, 0.5 * (c0 - c2) / curvature, 0.0)
    offset = np.where(best == i, np.clip(offset, -0.5, 0.5), 0.0)            # not at the range's ends
    step = float(candidates[1] - candidates[0])
    disparity = (candidates[best] + offset * step).astype(np.float32)
    index = np.arange(n)[:, None, None]
    far = np.where(np.abs(index - best[None]) >= 3, cost, np.inf).min(axis=0)
    least = np.take_along_axis(cost, best[None], 0)[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        confidence = np.clip(np.where(far > 0, 1.0 - least / far, 0.0), 0.0, 1.0).astype(np.float32)
    return Disparity(disparity, confidence, candidates)


def disparity_to_depth(disparity: np.ndarray, baseline_m: float, focal_px: float, focus_m: float) -> np.ndarray:
    """Depth (H, W) float32, metres along the optical axis, of a disparity map: ``1 / (d / (B f) + 1 / Z0)``; NaN
    where that is not a positive distance."""
    with np.errstate(divide="ignore", invalid="ignore"):
        z = 1.0 / (np.asarray(disparity, np.float64) / (baseline_m * focal_px) + 1.0 / focus_m)
    return np.where(np.isfinite(z) & (z > 0), z, np.nan).astype(np.float32)


def score_disparity(disparity: np.ndarray, truth: np.ndarray, *, border: int = BORDER_PX,
                    threshold: float = BADPIX_THRESHOLD) -> dict:
    """The benchmark's scores of a disparity map against its ground truth, ``border`` pixels left out on each side
    and pixels where either is not finite left out too.

    Returns:
        ``{"badpix_0.07": percent of pixels off by more than ``threshold``, "mse_x100": 100 x the mean squared
        error, "pixels": pixels scored}``.
    """
    d, g = np.asarray(disparity, np.float64), np.asarray(truth, np.float64)
    if d.shape != g.shape:
        raise ValueError(f"the disparity map is {d.shape} and its ground truth {g.shape}")
    inner = np.zeros(d.shape, bool)
    inner[border:d.shape[0] - border, border:d.shape[1] - border] = True
    valid = inner & np.isfinite(d) & np.isfinite(g)
    n = int(valid.sum())
    if n == 0:
        raise ValueError("no pixel to score (the border leaves none, or nothing is finite)")
    err = d[valid] - g[valid]
    return {f"badpix_{threshold:g}": 100.0 * float(np.mean(np.abs(err) > threshold)),
            "mse_x100": 100.0 * float(np.mean(err ** 2)), "pixels": n}
