"""Which primary rays can meet the objects at all: cones around tiles of rays against bounding spheres.

A view camera's rays or a light field's rays are the same from frame to frame, and most of them miss the
synthetic objects (at the paper's resolution Fig. 4's cube covers 6 % of the view's rays): casting them and
reading their misses back was most of a fast-path view render. The rays are cut once into tiles of
:data:`TILE` consecutive rays (a few neighbouring pixels or light field directions with their samples); each
tile gets a cone that holds every ray of it (an apex, an axis, a half-angle and the radius within which the rays'
origins lie around the apex). A frame then casts only the rays of the tiles whose cone meets some object's
bounding sphere. The test is conservative, so the rays left out are rays that miss: the render is unchanged.

A ray from an origin within ``spread`` of the apex passes within ``spread`` of where the same direction from the
apex passes, so a tile meets a sphere (centre s, radius R) if its apex cone meets the sphere of radius
R + ``spread``: the angle between the axis and s - apex is at most the half-angle plus the sphere's angular
radius asin((R + spread) / |s - apex|), or the apex lies inside it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["TILE", "RayTiles", "bounding_spheres"]

TILE = 32                  # rays per tile (8 pixels or light field directions of 4 samples)
MARGIN_RAD = 1e-4          # added to every cone's half-angle: float32 rays are not exactly what was measured


@dataclass(frozen=True)
class RayTiles:
    """Cones around tiles of consecutive rays.

    Attributes:
        count: number of rays N.
        apex: (T, 3) float64 a point of each tile (the mean origin), metres.
        axis: (T, 3) float64 unit mean direction.
        half_angle: (T,) float64 largest angle between a ray of the tile and the axis, radians (+ margin).
        spread: (T,) float64 largest distance of a ray's origin from the apex, metres.
    """

    count: int
    apex: np.ndarray
    axis: np.ndarray
    half_angle: np.ndarray
    spread: np.ndarray

    def __post_init__(self) -> None:
        # the columns and terms :meth:`meeting` reads every frame, contiguous
        set_ = object.__setattr__
        set_(self, "_apex", [np.ascontiguousarray(self.apex[:, i]) for i in range(3)])
        set_(self, "_axis", [np.ascontiguousarray(self.axis[:, i]) for i in range(3)])
        h = np.minimum(self.half_angle, np.pi / 2)
        set_(self, "_cos_half", np.cos(h))
        set_(self, "_sin_half", np.sin(h))

    @classmethod
    def of(cls, origins: np.ndarray, directions: np.ndarray) -> "RayTiles":
        """Tiles of :data:`TILE` consecutive rays (the last one may be shorter, padded with its last ray).

        Args:
            origins: (N, 3) ray origins, metres.
            directions: (N, 3) unit directions.
        """
        n = len(origins)
        tiles = -(-n // TILE)
        pad = tiles * TILE - n
        o = np.asarray(origins, np.float64)
        d = np.asarray(directions, np.float64)
        if pad:
            o = np.concatenate([o, np.repeat(o[-1:], pad, axis=0)])
            d = np.concatenate([d, np.repeat(d[-1:], pad, axis=0)])
        o = o.reshape(tiles, TILE, 3)
        d = d.reshape(tiles, TILE, 3)
        d = d / np.linalg.norm(d, axis=-1, keepdims=True)
        apex = o.mean(axis=1)
        spread = np.linalg.norm(o - apex[:, None], axis=-1).max(axis=1)
        axis = d.sum(axis=1)
        axis /= np.maximum(np.linalg.norm(axis, axis=-1, keepdims=True), 1e-300)
        cos = np.clip(np.einsum("tsk,tk->ts", d, axis), -1.0, 1.0)
        half_angle = np.arccos(cos.min(axis=1)) + MARGIN_RAD
        return cls(count=n, apex=apex, axis=axis, half_angle=half_angle, spread=spread)

    def meeting(self, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
        """(T,) bool: the tiles with a ray that may meet one of the spheres.

        The angle test is done on cosines: the axis and s - apex are at most (half-angle + asin(reach / dist))
        apart, where cos of the sum is cos(h) cos(b) - sin(h) sin(b) (a half-angle plus radius past pi meets).

        Args:
            centres: (B, 3) sphere centres, metres.
            radii: (B,) radii, metres.
        """
        apex, axis, spread = self._apex, self._axis, self.spread
        cos_h, sin_h = self._cos_half, self._sin_half
        hit = self.half_angle >= np.pi / 2            # wider than a half-space: may meet anything
        for s, r in zip(np.asarray(centres, np.float64), np.asarray(radii, np.float64)):
            vx, vy, vz = s[0] - apex[0], s[1] - apex[1], s[2] - apex[2]
            dist = np.sqrt(vx * vx + vy * vy + vz * vz)
            reach = r + spread
            sin_b = np.minimum(reach / np.maximum(dist, 1e-300), 1.0)
            cos_b = np.sqrt(1.0 - sin_b * sin_b)
            along = vx * axis[0] + vy * axis[1] + vz * axis[2]            # |v| cos(angle)
            hit |= (dist <= reach) | (along >= dist * (cos_h * cos_b - sin_h * sin_b))
        return hit

    def rays(self, tiles: np.ndarray) -> np.ndarray:
        """(R,) int64 indices of the rays of the tiles ``tiles`` (a (T,) bool mask), in order."""
        first = np.flatnonzero(tiles) * TILE
        idx = (first[:, None] + np.arange(TILE)[None, :]).ravel()
        return idx[idx < self.count]


def bounding_spheres(scene) -> tuple[np.ndarray, np.ndarray]:
    """A bounding sphere of every shape of a Mitsuba scene (around its axis-aligned box).

    Returns:
        centres (B, 3) float64 and radii (B,) float64, metres.
    """
    centres, radii = [], []
    for shape in scene.shapes():
        box = shape.bbox()
        lo = np.array([box.min.x, box.min.y, box.min.z], np.float64).reshape(3)
        hi = np.array([box.max.x, box.max.y, box.max.z], np.float64).reshape(3)
        centres.append(0.5 * (lo + hi))
        radii.append(0.5 * np.linalg.norm(hi - lo) * (1 + 1e-6) + 1e-6)
    return np.array(centres).reshape(-1, 3), np.array(radii)
