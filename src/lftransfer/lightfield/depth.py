"""Depth of the real scene from a captured light field: the plane where neighbouring lenslets agree.

Neighbouring lenslets see the same real point from different directions. For a sample (k, d) of the light field
and a candidate depth z (distance from the array plane along its normal), the point its centre ray meets at z is
``x = c_k + z (u, v)``; every neighbouring lenslet k' sees x along ``(x - c_k') / z``. Where the surface lies at
z, those lenslets see (for a diffuse surface) the same radiance, so the depth of the sample is the candidate with
the smallest mean normalised difference (a plane sweep, as in multi-view stereo). The projection prefilter
(:mod:`lftransfer.transfer.projection`) uses it to know where each projected ray lands.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from lftransfer.lightfield.lightfield import LightField

#: Candidate depths of :func:`plane_sweep`, metres: 64 steps uniform in 1 / z from 2 to 40 cm in front of the array.
SWEEP_DEPTHS = 1.0 / np.linspace(1.0 / 0.02, 1.0 / 0.4, 64)

#: Samples darker than this fraction of the light field's 99th percentile get no depth (too little signal).
DARK_FRACTION = 0.02


def plane_sweep(lf: LightField, depths: np.ndarray = SWEEP_DEPTHS, neighbours: int = 18) -> np.ndarray:
    """Depth along each sample's centre ray where neighbouring lenslets see the same radiance.

    Args:
        lf: a light field of the lit real scene (K, V, U, 3) radiance, W m^-2 sr^-1 (e.g. the response to a
            white projection).
        depths: (M,) candidate depths, metres along the array's normal.
        neighbours: lenslets compared with each sample's own (nearest first).

    Returns:
        (K, V, U) float64 depth, metres; NaN where the sample is dark (below :data:`DARK_FRACTION` of the 99th
        percentile), masked, or seen by fewer than two neighbours at every candidate.

    Example:
        >>> depth = plane_sweep(response)          # doctest: +SKIP
        >>> np.nanmedian(depth)                    # doctest: +SKIP
    """
    depths = np.asarray(depths, float)
    if depths.ndim != 1 or not len(depths) or not np.all(depths > 0):
        raise ValueError(f"depths must be a non-empty 1-D array of positive metres, got shape {depths.shape}")
    array = lf.array
    a, f = array.half_width, array.focal_length
    mask = lf.mask()
    lum = lf.data.mean(-1)
    depth = np.full(lum.shape, np.nan)
    if not mask.any() or not np.any(lum[:, mask] > 0):
        return depth
    lit = (lum > DARK_FRACTION * np.percentile(lum[:, mask], 99)) & mask[None]
    ks, js, is_ = np.nonzero(lit)
    own = lf.data[ks, js, is_]
    uv = np.stack([lf.u[is_], lf.v[js]], -1)
    centres = array.centres
    neighbours = min(neighbours, array.K - 1)
    if neighbours < 2:
        return depth
    nb = cKDTree(centres).query(centres, neighbours + 1)[1][:, 1:]
    cost = np.full((len(depths), len(ks)), np.inf)
    ones = np.ones((len(ks), 1))
    for m, z in enumerate(depths):
        points = centres[ks] + z * uv
        acc, seen = np.zeros(len(ks)), np.zeros(len(ks))
        for q in range(neighbours):
            k2 = nb[ks, q]
            uv2 = (points - centres[k2]) / z
            ok = (np.abs(uv2) <= a).all(-1) & array.in_cell(-f * uv2)
            other = lf.lookup(np.where(ok, k2, -1), np.concatenate([uv2, ones], -1))
            diff = np.abs(other - own).sum(-1) / (other.sum(-1) + own.sum(-1) + 1e-12)
            acc += np.where(ok, diff, 0.0)
            seen += ok
        cost[m] = np.where(seen >= 2, acc / np.maximum(seen, 1), np.inf)
    found = np.isfinite(cost.min(0))
    depth[ks[found], js[found], is_[found]] = depths[np.argmin(cost, 0)[found]]
    return depth


__all__ = ["DARK_FRACTION", "SWEEP_DEPTHS", "plane_sweep"]
