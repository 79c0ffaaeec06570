"""A captured light field read beyond its lenslets' window: the edge of the window, checked against the depth.

No lenslet records light steeper than its window (|u|, |v| <= a; a hexagonal lenslet's window is its cell's
hexagon). Where a diffuse real surface sends that light, it looks much as it does from the window's edge, so a
steep direction can be read at the nearest direction the lenslet recorded (:func:`extend_beyond_window`). That
guess holds only while the steep ray still meets the real surface the edge saw: a small real object seen at the
window's edge is missed by the steeper rays beside it. With the real scene's depth (measured through the rig,
:func:`lftransfer.transfer.projection.measure_depth`), each steep direction is checked: the steep ray is followed
to the depth of the edge sample it reads, and kept only if the lenslet under that point sees a surface there
(:func:`steep_rays`, once per measured depth). The renderer reads the extended table
(:class:`lftransfer.render.lights.LightFieldLight`, ``window="edge"``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.ndimage import distance_transform_edt

from lftransfer.lightfield.lightfield import LightField

#: A steep ray is taken to meet the surface that the window's edge saw if the lenslet under the point where it
#: reaches that depth sees a surface within this fraction of it (the sweep's candidates are 1.3 to 9 % apart).
DEPTH_TOLERANCE = 0.5


@dataclass(frozen=True)
class SteepRays:
    """Which samples beyond a light field's window are read from its edge: the grid and, with a depth, the check.

    Depends only on the lens array, the angular grid and the real scene's depth, so it is computed once per
    measured depth (:func:`steep_rays`) and applied to every light field captured with it
    (:func:`extend_beyond_window`).

    Attributes:
        shape: (K, V, U) of the light fields it applies to.
        reach: how far beyond the window, in units of the window's half-width a.
        margin: samples added on each side of the (V, U) grid, at its spacing.
        source: (V + 2 margin, U + 2 margin) int64: each sample's nearest sample inside the window, an index into
            the V * U grid (inside the window: itself).
        index: with a depth, (K, V + 2 margin, U + 2 margin) int64: each sample's entry of the light field's
            (K V U) entries, ``source`` in its own lenslet, or K V U (an entry of zero) where the depth says the
            steep ray misses the real scene; None without a depth (every lenslet reads ``source``).
        kept: fraction of the steep samples (outside the window, within the reach) kept; 1 without a depth.
    """

    shape: tuple[int, int, int]
    reach: float
    margin: int
    source: np.ndarray
    index: np.ndarray | None
    kept: float

    @property
    def entries(self) -> np.ndarray:
        """(K, V + 2 margin, U + 2 margin) int64: the entry of the light field's (K V U) entries each sample of the
        extended table reads, K V U (an entry of zero) where the depth check dropped it."""
        if self.index is not None:
            return self.index
        K, V, U = self.shape
        return np.arange(K)[:, None, None] * (V * U) + self.source[None]

    def check(self, shape: tuple[int, ...]) -> None:
        """Raise ValueError unless light fields of ``shape`` ((K, V, U, ...)) are those these rays were found for."""
        if tuple(shape[:3]) != self.shape:
            raise ValueError(f"the steep rays were found for light fields of shape {self.shape}, this one is "
                             f"{tuple(shape[:3])}")


@dataclass(frozen=True)
class WindowExtension:
    """A light field's table extended beyond its window.

    Attributes:
        data: (K, V + 2 margin, U + 2 margin, 3) float32 radiance, W m^-2 sr^-1: the light field's samples in the
            middle, each sample outside the window the nearest one inside it (zero where the depth says the steep
            ray misses the real scene).
        margin: samples added on each side, at the light field's spacing.
    """

    data: np.ndarray
    margin: int


def steep_rays(lf: LightField, reach: float, depth: np.ndarray | None = None,
               tolerance: float = DEPTH_TOLERANCE) -> SteepRays:
    """The samples beyond ``lf``'s window out to |(u, v)| <= ``reach`` a, each read at the window's edge, and with
    ``depth`` checked: a steep sample is kept where its ray, followed to the depth of the edge sample it reads,
    lands where the lenslet below sees a surface within ``tolerance`` of that depth.

    Args:
        lf: a light field of the lens array and angular grid (only its shape and array are used).
        reach: how far beyond the window, in units of the window's half-width a (> 1).
        depth: (K, V, U) depth of each sample's centre ray, metres (NaN: unknown), or None: every steep sample
            takes its edge value.
        tolerance: relative depth difference within which the lenslet under a steep ray's point sees the same
            surface (:data:`DEPTH_TOLERANCE`).

    Returns:
        :class:`SteepRays`, for :func:`extend_beyond_window`.
    """
    if not reach > 1.0:
        raise ValueError(f"reach must be > 1 (in units of the window's half-width), got {reach}")
    K, V, U = lf.data.shape[:3]
    if depth is not None and np.shape(depth) != (K, V, U):
        raise ValueError(f"depth has shape {np.shape(depth)}, the light field needs {(K, V, U)}")
    array, a = lf.array, lf.array.half_width
    du, dv = 2.0 * a / U, 2.0 * a / V
    margin = int(np.ceil((reach - 1.0) * max(U, V) / 2.0)) + 1
    Ve, Ue = V + 2 * margin, U + 2 * margin
    mask = np.zeros((Ve, Ue), bool)
    mask[margin:margin + V, margin:margin + U] = lf.mask()
    rows, cols = distance_transform_edt(~mask, return_distances=False, return_indices=True)
    source = (rows - margin) * U + (cols - margin)                    # (Ve, Ue) nearest sample inside the window
    unchecked = SteepRays(shape=(K, V, U), reach=float(reach), margin=margin, source=source, index=None, kept=1.0)
    if depth is None:
        return unchecked
    ue = -a + (np.arange(Ue) - margin + 0.5) * du
    ve = -a + (np.arange(Ve) - margin + 0.5) * dv
    uu, vv = np.meshgrid(ue, ve)
    steep = ~mask & (uu**2 + vv**2 <= (reach * a) ** 2)
    keep = np.ones((K, Ve, Ue), bool)
    if steep.any():
        keep[:, steep] = _meets_surface(array, np.asarray(depth, np.float64).reshape(K, V * U), source[steep],
                                        np.stack([uu[steep], vv[steep]], -1),
                                        source[margin:margin + V, margin:margin + U], (U, V, du, dv, a), tolerance)
    kept = float(keep[:, steep].mean()) if steep.any() else 1.0
    return replace(unchecked, index=np.where(keep, unchecked.entries, K * V * U), kept=kept)


def extend_beyond_window(lf: LightField, steep: SteepRays) -> WindowExtension:
    """The light field's table out to |(u, v)| <= ``steep.reach`` a, read at the window's edge (and zero where
    ``steep``'s depth check dropped the steep ray).

    Args:
        lf: the captured light field (K, V, U, 3) radiance, W m^-2 sr^-1.
        steep: :func:`steep_rays` of a light field of the same shape.

    Returns:
        :class:`WindowExtension`.

    Example:
        >>> steep = steep_rays(captured, 1.5, depth)              # once per measured depth  # doctest: +SKIP
        >>> extend_beyond_window(captured, steep).data.shape      # doctest: +SKIP
        (120, 74, 74, 3)
    """
    steep.check(lf.data.shape)
    # one gather; a dropped sample reads the zero entry at the end
    entries = np.concatenate([lf.data.reshape(-1, 3), np.zeros((1, 3), lf.data.dtype)])
    return WindowExtension(data=entries[steep.entries].astype(np.float32, copy=False), margin=steep.margin)


def _meets_surface(array, depth: np.ndarray, source: np.ndarray, uv: np.ndarray, inside: np.ndarray, grid,
                   tolerance: float) -> np.ndarray:
    """Whether each lenslet's steep ray (u, v) meets the surface that its edge sample ``source`` saw.

    The ray from lenslet k's centre along (u, v) reaches the edge sample's depth z at y = c_k + z (u, v); the
    lenslet k' whose cell holds y sees y at (y - c_k') / z, nearly straight on. The ray is kept when k' sees a
    surface there within ``tolerance`` z, or when nothing can be checked (no depth at the edge, y off the array).

    Args:
        depth: (K, V * U) depths; source: (n,) the edge sample of each steep direction; uv: (n, 2) the steep
            directions; inside: (V, U) each grid sample's nearest sample inside the window.

    Returns:
        (K, n) bool.
    """
    U, V, du, dv, a = grid
    z = depth[:, source]                                                    # (K, n)
    y = array.centres[:, None, :] + z[..., None] * uv[None]                 # (K, n, 2)
    known = np.isfinite(z)
    k2 = np.full(z.shape, -1, np.int64)
    k2[known] = array.lenslet_at(y[known])
    check = known & (k2 >= 0)
    d = (y[check] - array.centres[k2[check]]) / z[check][:, None]
    iu = np.clip(np.floor((d[:, 0] + a) / du).astype(np.int64), 0, U - 1)
    iv = np.clip(np.floor((d[:, 1] + a) / dv).astype(np.int64), 0, V - 1)
    z2 = depth[k2[check], inside[iv, iu]]
    keep = np.ones(z.shape, bool)
    keep[check] = np.isfinite(z2) & (np.abs(z2 - z[check]) <= tolerance * z[check])
    return keep


__all__ = ["DEPTH_TOLERANCE", "SteepRays", "WindowExtension", "extend_beyond_window", "steep_rays"]
