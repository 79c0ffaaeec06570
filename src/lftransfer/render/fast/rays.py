"""The fast path's primary rays: the constant ray sets a renderer casts frame after frame (:class:`RaySets`,
recognised by identity), culled by tile from their second render on (:func:`rays_to_cast`), and the per-group
means summed over the rays that hit only (:func:`group_means`)."""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np

from lftransfer.render.culling import TILE, RayTiles, bounding_spheres
from lftransfer.render.base import SampleMeans, mean_depth

CULL_BELOW = 0.25           # primary rays are culled by tile when fewer than this share of the tiles may hit


@dataclass(eq=False)
class RaySet:
    """A constant ray set a renderer has cast (the memoised primary rays of a view or light field render).

    Attributes:
        origins, directions: weak references to its (N, 3) float32 arrays (identity is the key).
        renders: how many renders cast it.
        tiles: its cones for culling, once built (:func:`ray_tiles`).
        culled: the bounding spheres of the last culling and the rays cast for them (a still scene culls once).
        cast_rays: those rays' indices and the renderer's Dr.Jit rays gathered for them.
    """

    origins: weakref.ref
    directions: weakref.ref
    renders: int = 0
    tiles: RayTiles | None = None
    _centre: tuple = ()        # (centre,) once looked for
    culled: tuple | None = None    # (the spheres' bytes, the rays cast for them): :func:`rays_to_cast`'s last answer
    cast_rays: tuple | None = None  # (those rays' indices, their gathered Dr.Jit rays): kept by the renderer

    def centre(self) -> np.ndarray | None:
        """(3,) the one origin every ray starts from (a view camera), or None; looked for once, when first asked
        (a pass over every origin, which only glossy lobes read from the cache points need)."""
        if not self._centre:
            origins = self.origins()
            self._centre = (np.array(origins[0], np.float64) if np.all(origins == origins[0]) else None,)
        return self._centre[0]


class RaySets:
    """The constant ray sets a renderer has cast (a few, by weak reference)."""

    def __init__(self) -> None:
        self._sets: list[RaySet] = []

    def find(self, origins: np.ndarray, directions: np.ndarray) -> RaySet | None:
        """What the renderer knows of a constant ray set (the memoised primary rays, read-only, recognised by
        identity), with this render counted; None for other rays. A few sets are kept, by weak reference."""
        if origins.flags.writeable or directions.flags.writeable or not len(origins):
            return None
        sets = [r for r in self._sets if r.origins() is not None]
        found = next((r for r in sets if r.origins() is origins and r.directions() is directions), None)
        if found is None:
            found = RaySet(weakref.ref(origins), weakref.ref(directions))
            sets = [*sets[-7:], found]
        self._sets = sets
        found.renders += 1
        return found


def ray_tiles(ray_set: RaySet | None, origins: np.ndarray, directions: np.ndarray) -> RayTiles | None:
    """The cones around tiles of a constant ray set, built at the set's second render (a live loop renders the
    same rays every frame; the bounce loop draws new ones per bounce, where building the tiles would cost more
    than they save) and kept with the set; None for other rays, small sets and at a set's first render (cast
    whole)."""
    if ray_set is None or ray_set.renders < 2 or len(origins) < 64 * TILE:
        return None
    if ray_set.tiles is None:
        ray_set.tiles = RayTiles.of(origins, directions)
    return ray_set.tiles


def rays_to_cast(ray_set: RaySet | None, origins: np.ndarray, directions: np.ndarray, scene) -> np.ndarray | None:
    """(C,) int64 indices of the rays to cast, those of the tiles whose cone meets an object's bounding sphere in
    ``scene`` (:mod:`lftransfer.render.culling`: the rays left out miss), where fewer than ``CULL_BELOW`` of the
    tiles may hit; None: cast every ray (no tiles, or too many of them may hit). The answer is kept with the ray
    set and given again (the same read-only array) while the spheres stay where they were."""
    tiles = ray_tiles(ray_set, origins, directions)
    if tiles is None:
        return None
    spheres = bounding_spheres(scene)
    key = (spheres[0].tobytes(), spheres[1].tobytes())
    if ray_set.culled is not None and ray_set.culled[0] == key:     # nothing moved since the last render
        return ray_set.culled[1]
    chosen = tiles.meeting(*spheres)
    cast = tiles.rays(chosen) if chosen.mean() < CULL_BELOW else None
    if cast is not None:
        cast.flags.writeable = False
    ray_set.culled = (key, cast)
    return cast


def group_means(idx: np.ndarray, colour: np.ndarray, t_hit: np.ndarray, groups: int, spp: int) -> SampleMeans:
    """:class:`SampleMeans` of ``groups`` groups of ``spp`` consecutive rays from the rays that hit only.

    The sums run over the groups with a hit (a view's objects cover a few per cent of its pixels), in float64 as
    a full-size ``np.bincount`` would sum them; the other groups are written once (black, coverage 0, depth inf).

    Args:
        idx: (H,) int64 ray indices of the hits, ascending.
        colour: (H, 3) float32 their radiance.
        t_hit: (H,) float32 their hit distances, metres.
        groups: G, the number of groups.
        spp: rays per group.
    """
    scale = 1.0 / spp
    radiance = np.zeros((groups, 3), np.float32)
    coverage = np.zeros(groups, np.float32)
    depth = np.full(groups, np.inf, np.float32)
    if len(idx):
        group = idx // spp
        first = np.empty(len(group), bool)          # the first hit of each group with a hit
        first[0] = True
        np.not_equal(group[1:], group[:-1], out=first[1:])
        dense = np.cumsum(first) - 1                # each hit's group among those with a hit
        hit = group[first]
        n = len(hit)
        flat = radiance.reshape(-1)
        for c in range(3):
            flat[hit * 3 + c] = np.bincount(dense, weights=colour[:, c], minlength=n) * scale
        hits = np.bincount(dense, minlength=n).astype(np.float32)
        coverage[hit] = hits * np.float32(scale)
        depth[hit] = mean_depth(np.bincount(dense, weights=t_hit, minlength=n), hits)
    return SampleMeans(radiance=radiance, coverage=coverage, depth=depth)
