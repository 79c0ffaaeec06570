"""The lens array in the plane z = 0: lattice geometry, lenslet cells and apertures.

World frame (docs/architecture.md, "The interface"): metres, the array plane is z = 0, +y up, the real half-space
is z > 0.
Lenslets are numbered row-major, ``k = r * cols + c``, with row 0 at the top (largest y).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Literal

import numpy as np
from scipy.spatial import Delaunay, cKDTree

from lftransfer.optics.geometry import rotation_2d

__all__ = ["LensArray"]

_SQRT3 = math.sqrt(3.0)
_PLASTIC = 1.32471795724474602596  # generator of the R2 low-discrepancy sequence
_R2_ALPHA = np.array([1.0 / _PLASTIC, 1.0 / _PLASTIC**2])
_EDGE_TOL = 1e-9  # relative tolerance of the cell tests (points on a cell border count as inside)


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class LensArray:
    """A planar array of identical lenslets on a hexagonal or rectangular lattice.

    Attributes:
        lattice: ``"hex"`` (rows offset by half a pitch, row spacing ``pitch * sqrt(3) / 2``) or ``"rect"``.
        rows: Number of lattice rows.
        cols: Number of lenslets per row.
        pitch: Centre spacing along a row, metres.
        focal_length: Focal length of every lenslet, metres.
        aperture: ``"cell"``: the lenslets tile the plane, each aperture is its lattice cell;
            ``"round"``: round lenses of diameter ``pitch`` with gaps between them.
        offset: In-plane translation (x, y) of the lattice, metres.
        rotation: In-plane rotation of the lattice about +z, radians.
    """

    lattice: Literal["hex", "rect"]
    rows: int
    cols: int
    pitch: float
    focal_length: float
    aperture: Literal["cell", "round"] = "cell"
    offset: tuple[float, float] = (0.0, 0.0)
    rotation: float = 0.0

    def __post_init__(self) -> None:
        if self.lattice not in ("hex", "rect"):
            raise ValueError(f"lattice must be 'hex' or 'rect', got {self.lattice!r}")
        if self.aperture not in ("cell", "round"):
            raise ValueError(f"aperture must be 'cell' or 'round', got {self.aperture!r}")
        for name in ("rows", "cols"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
            object.__setattr__(self, name, int(value))
        for name in ("pitch", "focal_length"):
            value = float(getattr(self, name))
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive finite length in metres, got {value!r}")
            object.__setattr__(self, name, value)
        try:
            offset = tuple(float(x) for x in self.offset)
        except TypeError as exc:
            raise ValueError(f"offset must be a pair (x, y) in metres, got {self.offset!r}") from exc
        if len(offset) != 2 or not all(math.isfinite(x) for x in offset):
            raise ValueError(f"offset must be a finite pair (x, y) in metres, got {self.offset!r}")
        object.__setattr__(self, "offset", offset)
        rotation = float(self.rotation)
        if not math.isfinite(rotation):
            raise ValueError(f"rotation must be a finite angle in radians, got {self.rotation!r}")
        object.__setattr__(self, "rotation", rotation)

    # ------------------------------------------------------------------ sizes
    @property
    def K(self) -> int:
        """Number of lenslets, ``rows * cols``."""
        return self.rows * self.cols

    @property
    def half_width(self) -> float:
        """Angular half-width ``a = (pitch / 2) / focal_length`` of the (u, v) grid (dimensionless tangent)."""
        return 0.5 * self.pitch / self.focal_length

    @property
    def cell_area(self) -> float:
        """Area of one lattice cell, m^2: ``pitch^2 sqrt(3) / 2`` (hex) or ``pitch^2`` (rect)."""
        return self.pitch**2 * (_SQRT3 / 2.0 if self.lattice == "hex" else 1.0)

    @property
    def aperture_area(self) -> float:
        """Area of one lenslet aperture, m^2: the cell area, or ``pi (pitch / 2)^2`` for round lenses."""
        return self.cell_area if self.aperture == "cell" else math.pi * (0.5 * self.pitch) ** 2

    # --------------------------------------------------------------- geometry
    @cached_property
    def _rot(self) -> np.ndarray:
        return rotation_2d(self.rotation)

    @cached_property
    def centres(self) -> np.ndarray:
        """Lenslet optical centres, ``(K, 2) float64`` (x, y) in metres, row-major, row 0 on top (read-only)."""
        r, c = np.divmod(np.arange(self.K), self.cols)
        if self.lattice == "rect":
            x = (c - (self.cols - 1) / 2.0) * self.pitch
            y = ((self.rows - 1) / 2.0 - r) * self.pitch
            local = np.stack([x, y], axis=-1)
        else:
            x = c * self.pitch + (r % 2) * 0.5 * self.pitch
            y = -r * self.pitch * _SQRT3 / 2.0
            local = np.stack([x, y], axis=-1)
            local = local - local.mean(axis=0)
        world = local @ self._rot.T + np.asarray(self.offset)
        return _readonly(np.ascontiguousarray(world, dtype=np.float64))

    @property
    def centres3d(self) -> np.ndarray:
        """Lenslet optical centres in 3-D, ``(K, 3) float64`` metres, z = 0."""
        return np.concatenate([self.centres, np.zeros((self.K, 1))], axis=1)

    def cell_vertices(self) -> np.ndarray:
        """Vertices of the lattice cell around a centre at the origin, in world orientation.

        The hexagonal cell is the Voronoi cell of the lattice ("pointy-top": vertices at 30 + 60 i degrees plus
        ``rotation``, circumradius ``pitch / sqrt(3)``); the rectangular cell is a square of side ``pitch``.

        Returns:
            ``(6, 2)`` (hex) or ``(4, 2)`` (rect) float64 vertices in metres, counter-clockwise.
        """
        if self.lattice == "hex":
            angles = np.deg2rad(30.0 + 60.0 * np.arange(6)) + self.rotation
            radius = self.pitch / _SQRT3
        else:
            angles = np.deg2rad(45.0 + 90.0 * np.arange(4)) + self.rotation
            radius = self.pitch / math.sqrt(2.0)
        return radius * np.stack([np.cos(angles), np.sin(angles)], axis=-1)

    def _to_local(self, offsets: np.ndarray) -> np.ndarray:
        offsets = np.asarray(offsets, dtype=np.float64)
        if offsets.ndim < 1 or offsets.shape[-1] != 2:
            raise ValueError(f"offsets must have shape (..., 2), got {offsets.shape}")
        return offsets @ self._rot  # R^T applied to row vectors

    def in_cell(self, offsets: np.ndarray) -> np.ndarray:
        """Whether offsets from a lenslet centre lie in its lattice cell (borders included).

        Args:
            offsets: ``(..., 2)`` in-plane offsets from a centre, metres (world orientation).

        Returns:
            ``(...) bool``.
        """
        local = self._to_local(offsets)
        half = 0.5 * self.pitch * (1.0 + _EDGE_TOL)
        x, y = local[..., 0], local[..., 1]
        if self.lattice == "rect":
            return (np.abs(x) <= half) & (np.abs(y) <= half)
        s = _SQRT3 / 2.0
        return (np.abs(x) <= half) & (np.abs(0.5 * x + s * y) <= half) & (np.abs(-0.5 * x + s * y) <= half)

    def in_aperture(self, offsets: np.ndarray) -> np.ndarray:
        """Whether offsets from a lenslet centre lie in its aperture (the cell, or a disk of diameter pitch).

        Args:
            offsets: ``(..., 2)`` in-plane offsets from a centre, metres.

        Returns:
            ``(...) bool``.
        """
        if self.aperture == "cell":
            return self.in_cell(offsets)
        offsets = np.asarray(offsets, dtype=np.float64)
        if offsets.ndim < 1 or offsets.shape[-1] != 2:
            raise ValueError(f"offsets must have shape (..., 2), got {offsets.shape}")
        return np.hypot(offsets[..., 0], offsets[..., 1]) <= 0.5 * self.pitch * (1.0 + _EDGE_TOL)

    @cached_property
    def _tree(self) -> cKDTree:
        return cKDTree(self.centres)

    def lenslet_at(self, points: np.ndarray) -> np.ndarray:
        """Index of the lenslet whose lattice cell contains each point.

        Args:
            points: ``(..., 2)`` points (x, y) in the array plane, metres.

        Returns:
            ``(...) int64`` lenslet indices, -1 for points outside every cell of the array.
        """
        points = np.asarray(points, dtype=np.float64)
        if points.ndim < 1 or points.shape[-1] != 2:
            raise ValueError(f"points must have shape (..., 2), got {points.shape}")
        flat = points.reshape(-1, 2)
        finite = np.all(np.isfinite(flat), axis=1)
        k = np.full(len(flat), -1, dtype=np.int64)
        if np.any(finite):
            _, idx = self._tree.query(flat[finite], workers=-1)
            idx = idx.astype(np.int64)
            inside = self.in_cell(flat[finite] - self.centres[idx])
            k[finite] = np.where(inside, idx, -1)
        return k.reshape(points.shape[:-1])

    @cached_property
    def _shear(self) -> np.ndarray:
        """(2, 2) affine map under which the lattice's Delaunay triangles are unique and alike: the identity on a
        hex lattice (equilateral triangles), a slight shear on a rect one (whose squares have two diagonals)."""
        if self.lattice == "hex":
            return np.eye(2)
        return self._rot @ np.array([[1.0, 0.1], [0.0, 1.0]]) @ self._rot.T

    @cached_property
    def _triangulation(self) -> Delaunay:
        return Delaunay(self.centres @ self._shear.T)

    def interpolation(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Weights of a continuous (piecewise-linear) reconstruction across lenslets at a point of the plane.

        A quantity sampled once per lenslet (at its centre) is read at a point as the barycentric blend of the
        three lenslets at the corners of the lattice triangle that contains it (equilateral triangles on a hex lattice,
        squares cut along the same diagonal on a rect one; barycentric weights are affine-invariant, so they are
        found in a slightly sheared copy of the plane where this triangulation is the unique Delaunay one). Each lenslet's
        weight is a hat function that is 1 at its centre and integrates to its cell area, so the reconstruction
        keeps every lenslet's flux. Points outside the triangulated hull (the outer half cell) read their own
        lenslet alone (weight 1), as the box reconstruction does.

        Args:
            points: ``(..., 2)`` points (x, y) in the array plane, metres.

        Returns:
            ``(..., 3) int64`` lenslet indices and ``(..., 3) float64`` weights summing to 1 (-1 and 0 for points
            outside every cell).

        Example:
            >>> idx, w = array.interpolation(array.centres)   # each centre reads itself with weight 1
        """
        points = np.asarray(points, dtype=np.float64)
        if points.ndim < 1 or points.shape[-1] != 2:
            raise ValueError(f"points must have shape (..., 2), got {points.shape}")
        flat = points.reshape(-1, 2) @ self._shear.T
        idx = np.full((len(flat), 3), -1, dtype=np.int64)
        w = np.zeros((len(flat), 3))
        tri = self._triangulation
        finite = np.all(np.isfinite(flat), axis=1)
        simplex = np.full(len(flat), -1, dtype=np.int64)
        simplex[finite] = tri.find_simplex(flat[finite])
        inside = simplex >= 0
        t = tri.transform[simplex[inside]]                                  # (n, 3, 2): barycentric maps
        b = np.einsum("nij,nj->ni", t[:, :2], flat[inside] - t[:, 2])
        idx[inside] = tri.simplices[simplex[inside]]
        w[inside] = np.clip(np.concatenate([b, 1.0 - b.sum(1, keepdims=True)], axis=1), 0.0, 1.0)
        w[inside] /= w[inside].sum(1, keepdims=True)
        own = self.lenslet_at(points.reshape(-1, 2)[~inside])
        idx[~inside, 0] = own
        w[~inside, 0] = (own >= 0).astype(np.float64)
        return idx.reshape(points.shape[:-1] + (3,)), w.reshape(points.shape[:-1] + (3,))

    def sample_aperture(self, n: int, seed: int = 0) -> np.ndarray:
        """Well-stratified offsets uniformly covering one lenslet aperture.

        An R2 low-discrepancy sequence, randomly shifted (Cranley-Patterson rotation drawn from ``seed``), over
        the aperture's bounding box in the lattice's local frame, with rejection of points outside the aperture.
        Deterministic for a given ``(n, seed)``.

        Args:
            n: Number of offsets (>= 0).
            seed: Scrambling seed.

        Returns:
            ``(n, 2) float64`` offsets from the lenslet centre, metres, world orientation.
        """
        n = int(n)
        if n < 0:
            raise ValueError(f"n must be >= 0, got {n}")
        p = self.pitch
        if self.aperture == "round":
            box = np.array([p, p])
            accept = math.pi / 4.0
        elif self.lattice == "hex":
            box = np.array([p, 2.0 * p / _SQRT3])
            accept = 0.75
        else:
            box = np.array([p, p])
            accept = 1.0
        shift = np.random.default_rng(seed).random(2)
        out = np.empty((0, 2))
        m = int(math.ceil(n / accept * 1.1)) + 16
        while len(out) < n:
            i = np.arange(1, m + 1, dtype=np.float64)[:, None]
            unit = np.mod(shift + i * _R2_ALPHA, 1.0)
            local = (unit - 0.5) * box
            world = local @ self._rot.T
            keep = self.in_aperture(world)
            out = world[keep]
            m *= 2
        return np.ascontiguousarray(out[:n])

    def extent(self) -> tuple[float, float, float, float]:
        """Bounding box of all lattice cells of the array.

        Returns:
            ``(xmin, xmax, ymin, ymax)`` in metres.
        """
        pts = (self.centres[:, None, :] + self.cell_vertices()[None, :, :]).reshape(-1, 2)
        return (float(pts[:, 0].min()), float(pts[:, 0].max()), float(pts[:, 1].min()), float(pts[:, 1].max()))
