"""How the light field light reads the captured light field, precomputed once per rig, seed or steep-ray set:
the aperture points of the area model (:func:`aperture_points`), the linear reconstruction's blend
(:func:`linear_blend`), the table extended beyond the lenslets' window (``window="edge"``,
:func:`extended_table`) and the raster of the array plane that finds the lenslets a ray meets
(:func:`plane_lookup`)."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from lftransfer.backend import mitsuba
from lftransfer.choices import LENSLET_RECONSTRUCTION, RECONSTRUCTIONS, Reconstruction
from lftransfer.lightfield.window import SteepRays
from lftransfer.render.lights.jit import jit_array

#: How far ``window="edge"`` reads beyond the window: |(u, v)| <= EDGE_REACH a (36.9 degrees off the normal for
#: a = 0.5). Measured on Fig. 4 and five other scenes (benchmarks/reconstruction/window.py; docs/architecture.md, "Light
#: from beyond the window", says why):
#: 1.5 brings the synthetic side's energy to within 1 % of the ground truth's on the four whose real objects
#: stand near the synthetic ones; unbounded it overshoots by 3 to 5 % and the error grows again.
EDGE_REACH = 1.5


def extended_table(data: np.ndarray, steep: SteepRays):
    """:func:`~lftransfer.lightfield.window.extend_beyond_window`'s table, gathered by Dr.Jit: mi.Float
    (K * Ve * Ue * 3,), equal to ``extend_beyond_window(lf, steep).data.ravel()`` bit for bit.

    The gather's index depends only on ``steep`` and is uploaded once per :class:`SteepRays` (a live loop builds a
    light per frame from the same one); per frame only the light field itself is uploaded (a third of the
    extended table) and the gather runs on the renderer's threads.

    Args:
        data: (K, V, U, 3) float32 radiance, C-contiguous.
        steep: :func:`~lftransfer.lightfield.window.steep_rays` of light fields of this shape.
    """
    import drjit as dr

    mi = mitsuba()
    steep.check(data.shape)
    index = _edge_index(steep, mi.variant())
    table = dr.gather(mi.Float, jit_array(mi.Float, data), index, index < data.size)   # 0 past the end
    dr.eval(table)
    dr.sync_thread()        # finished here, so that a stage timer charges the gather to the light's construction
    return table


_EDGE_INDEX: list = []      # (SteepRays, variant, mi.UInt32) of the last few steep-ray sets, newest last


def _edge_index(steep: SteepRays, variant: str):
    """mi.UInt32 (K * Ve * Ue * 3,) the float each entry of the extended table reads (3 K V U: zero), per steep-ray
    set (recognised by identity; a few are kept)."""
    mi = mitsuba()
    for kept, var, index in _EDGE_INDEX:
        if kept is steep and var == variant:
            return index
    floats = steep.entries.astype(np.uint32)[..., None] * np.uint32(3) + np.arange(3, dtype=np.uint32)
    index = jit_array(mi.UInt32, floats)
    del _EDGE_INDEX[:-3]
    _EDGE_INDEX.append((steep, variant, index))
    return index


@functools.lru_cache(maxsize=16)
def aperture_points(array, pool: int, seed: int) -> np.ndarray:
    """(pool, 2) float32 aperture offsets of an area model, metres (``LensArray.sample_aperture``): the same for
    every light of a rig and seed, so found once (a live loop builds a light per frame)."""
    points = array.sample_aperture(pool, seed=seed).astype(np.float32)
    points.flags.writeable = False
    return points


@dataclass(frozen=True)
class LinearBlend:
    """The linear reconstruction's lenslets and weights at every aperture point of every lenslet.

    Attributes:
        index: (K * P * 3,) uint32 lenslets read (P aperture points, three corners each).
        weight: (K * P * 3,) float32 their barycentric weights.
        reads: (K, K) bool: lenslet k's aperture reads lenslet j.
    """

    index: np.ndarray
    weight: np.ndarray
    reads: np.ndarray


@functools.lru_cache(maxsize=16)
def linear_blend(array, pool: int, seed: int) -> LinearBlend:
    """:class:`LinearBlend` at the aperture points of :func:`aperture_points` (``pool`` 0: the lenslets'
    centres), found once per rig and seed: 38 ms at the paper's 120 lenslets and 1024 points."""
    offsets = aperture_points(array, pool, seed) if pool else np.zeros((1, 2), np.float32)
    K = array.K
    idx, w = array.interpolation(array.centres[:, None, :] + offsets[None].astype(np.float64))   # (K, P, 3)
    idx = np.where(w > 0, idx, np.arange(K)[:, None, None])
    reads = np.zeros((K, K), bool)
    reads[np.repeat(np.arange(K), idx.shape[1] * 3), idx.ravel()] = True
    blend = LinearBlend(index=idx.astype(np.uint32).ravel(), weight=w.astype(np.float32).ravel(), reads=reads)
    for a in (blend.index, blend.weight, blend.reads):
        a.flags.writeable = False
    return blend


@dataclass(frozen=True)
class PlaneLookup:
    """A raster of the array plane: which lenslets send light from each cell, and with what weight.

    Attributes:
        x0, y0: corner of the raster (the array's extent), metres.
        cell: cell size, metres (pitch / 64).
        nx, ny: raster size.
        terms: lenslets per cell, 1 (``"box"``) or 3 (``"linear"``).
        lenslets: mi.UInt32 (ny * nx * 3,) lenslet indices per cell (row-major, y then x).
        weights: mi.Float (ny * nx * 3,) their weights, zero outside every aperture.
        own: mi.UInt32 (ny * nx,) the lenslet whose aperture contains the cell's centre, K outside every aperture.
    """

    x0: float
    y0: float
    cell: float
    nx: int
    ny: int
    terms: int
    lenslets: object
    weights: object
    own: object


PLANE_CELLS_PER_PITCH = 64


def plane_lookup(array, reconstruction: Reconstruction = LENSLET_RECONSTRUCTION) -> PlaneLookup:
    """The :class:`PlaneLookup` of a lens array, cached per array and reconstruction.

    Each cell is read at its centre: ``"box"``, the lenslet whose aperture contains it
    (:meth:`LensArray.lenslet_at` and :meth:`LensArray.in_aperture`); ``"linear"``, the three lenslets and
    weights of :meth:`LensArray.interpolation` there (inside an aperture only). A point is therefore read as
    the nearest cell centre reads it, at most pitch / 128 away.
    """
    if reconstruction not in RECONSTRUCTIONS:
        raise ValueError(f"reconstruction must be one of {RECONSTRUCTIONS}, got {reconstruction!r}")
    return _plane_lookup(array, reconstruction, mitsuba().variant())


@functools.lru_cache(maxsize=8)
def _plane_lookup(array, reconstruction: str, variant: str) -> PlaneLookup:
    mi = mitsuba()
    cell = array.pitch / PLANE_CELLS_PER_PITCH
    xmin, xmax, ymin, ymax = array.extent()
    nx, ny = int(np.ceil((xmax - xmin) / cell)), int(np.ceil((ymax - ymin) / cell))
    gx = xmin + (np.arange(nx) + 0.5) * cell
    gy = ymin + (np.arange(ny) + 0.5) * cell
    centres = np.stack(np.meshgrid(gx, gy), axis=-1).reshape(-1, 2)          # (ny * nx, 2), row-major
    own = array.lenslet_at(centres)
    inside = own >= 0
    inside[inside] = array.in_aperture(centres[inside] - array.centres[own[inside]])
    idx = np.zeros((len(centres), 3), np.int64)
    w = np.zeros((len(centres), 3), np.float64)
    if reconstruction == "box":
        idx[inside, 0] = own[inside]
        w[inside, 0] = 1.0
    else:
        idx[inside], w[inside] = array.interpolation(centres[inside])
        w[idx < 0] = 0.0
        idx[idx < 0] = 0
    own = np.where(inside, own, array.K)
    return PlaneLookup(float(xmin), float(ymin), float(cell), nx, ny, 1 if reconstruction == "box" else 3,
                       jit_array(mi.UInt32, idx.astype(np.uint32).ravel()),
                       jit_array(mi.Float, w.astype(np.float32).ravel()), jit_array(mi.UInt32, own.astype(np.uint32)))
