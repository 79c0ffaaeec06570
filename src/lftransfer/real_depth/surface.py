"""The real surface as the rig measures it, in the lens array's frame: points, normals and a confidence per point,
from the LF camera's per-entry depth (:func:`~lftransfer.transfer.projection.measure_depth`). What the projection
solve lights (:mod:`lftransfer.transfer.surface_solve`); no model of the real objects' material is involved."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from lftransfer.lightfield import LightField

__all__ = ["CELL_M", "MeasuredSurface", "NORMAL_NEIGHBOURS", "measured_surface"]

CELL_M = 0.003              # the surface's sampling: one point per cell of this side, metres
NORMAL_NEIGHBOURS = 12      # points of the local plane fitted for a normal


@dataclass(frozen=True)
class MeasuredSurface:
    """Samples of the measured real surface, array frame (the array in z = 0, the real objects at z > 0).

    Attributes:
        points: (N, 3) float64, metres: the mean of the light field entries' surface points in each cell.
        normals: (N, 3) float64 unit, facing the array (z < 0): the normal of the plane fitted to the
            :data:`NORMAL_NEIGHBOURS` nearest points.
        confidence: (N,) float64 in (0, 1]: how many entries measured the cell, against the median cell (1 at or
            above it; a cell seen by one entry among many weighs less).
        depth: (K, V, U) the per-entry depth it came from, metres along the array's normal (NaN: unknown).
    """

    points: np.ndarray
    normals: np.ndarray
    confidence: np.ndarray
    depth: np.ndarray

    def __len__(self) -> int:
        return len(self.points)

    def shifted(self, dz_m: float) -> "MeasuredSurface":
        """The same surface moved ``dz_m`` metres along the array's normal (a wrong depth: a negative control)."""
        return MeasuredSurface(self.points + np.array([0.0, 0.0, dz_m]), self.normals, self.confidence,
                               self.depth + dz_m)


def measured_surface(depth: np.ndarray, array, U: int, V: int, *, cell_m: float = CELL_M) -> MeasuredSurface:
    """Points, normals and confidence of the real surface from a per-entry depth.

    Args:
        depth: (K, V, U) depth of each light field entry's centre ray, metres along the array's normal (NaN:
            unknown).
        array: the lens array (the rig model's).
        U, V: the light field grid.
        cell_m: the side of the cells the entries' points are averaged over, metres.

    Returns:
        :class:`MeasuredSurface` (no points where no entry has a depth).
    """
    depth = np.asarray(depth, float)
    if depth.shape != (array.K, V, U):
        raise ValueError(f"depth has shape {depth.shape}, expected {(array.K, V, U)}")
    grid = LightField.zeros(array, U, V)
    k, j, i = np.nonzero(np.isfinite(depth) & grid.mask()[None])
    z = depth[k, j, i]
    c = array.centres[k]
    pts = np.stack([c[:, 0] + z * grid.u[i], c[:, 1] + z * grid.v[j], z], -1)
    if not len(pts):
        empty = np.zeros((0, 3))
        return MeasuredSurface(empty, empty, np.zeros(0), depth)
    _, cell, counts = np.unique(np.floor(pts / cell_m).astype(np.int64), axis=0, return_inverse=True,
                                return_counts=True)
    cell = cell.ravel()
    points = np.zeros((len(counts), 3))
    np.add.at(points, cell, pts)
    points /= counts[:, None]
    n = min(NORMAL_NEIGHBOURS, len(points))
    normals = np.tile([0.0, 0.0, -1.0], (len(points), 1))
    if n >= 3:
        _, idx = cKDTree(points).query(points, k=n)
        near = points[idx] - points[idx].mean(axis=1, keepdims=True)              # (N, n, 3)
        _, vectors = np.linalg.eigh(np.einsum("pki,pkj->pij", near, near))
        normals = vectors[:, :, 0]                                                   # the smallest spread
        normals *= np.where(normals[:, 2] > 0, -1.0, 1.0)[:, None]                   # facing the array
    confidence = np.minimum(1.0, np.sqrt(counts / max(float(np.median(counts)), 1.0)))
    return MeasuredSurface(points, normals, confidence, depth)
