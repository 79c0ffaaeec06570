"""The room's steep light on the real side, sent at the lenslets' angles (docs/architecture.md, "The light probe").

In a lit room the array's panel shades the real objects from the room behind it. The synthetic side's lenslet
cameras see that room behind the synthetic objects, and the projector sends it on, but only along the directions a
lenslet covers (|u|, |v| <= a, about 26.6 degrees off the array's normal): a real point close to the array sees the
panel over most of its sky, and the window is a third of that. A projector cannot send light along the steeper
directions, but a diffuse surface does not tell where its irradiance comes from: the room seen in the window is
sent stronger by the ratio of the irradiance the whole panel would pass to the irradiance the window passes.

The ratio depends on where the light lands: each light field entry's landing point is the measured depth along
its centre ray (the projection prefilter's, :func:`~lftransfer.transfer.projection.measure_depth`); entries
without a depth are not changed. The irradiance is taken on a surface facing the array (normal -z): the faces
that receive light through the array face it, and the real objects' normals are not known. The ratio is found
from the light probe's map on a grid of points in front of the array and read there trilinearly. Under the
projection solved against the measured surface (:mod:`~lftransfer.transfer.surface_solve`) the room's part of each
measured point's target irradiance gets the factor at that point, and the solve finds the light field that gives it.
"""

from __future__ import annotations

import numpy as np

from lftransfer.optics.geometry import crosses_rectangle, env_directions, env_solid_angles, in_window

__all__ = ["MAX_GAIN", "landing_points", "room_gain_at", "steep_room_gain"]

MAX_GAIN = 8.0                     # the room's window light is sent at most this much stronger
GRID_XY = 9                        # grid points across the array's extent, per axis
GRID_DEPTHS = np.geomspace(0.01, 0.5, 12)   # metres in front of the array


def _gain_at(points: np.ndarray, radiance: np.ndarray, extent, a: float) -> np.ndarray:
    """(P,) the ratio of the room's irradiance through the whole panel to that through the lenslets' window, on
    a surface facing the array at ``points`` (P, 3) (array frame, z > 0); 1 where the window passes none."""
    h, w = radiance.shape[:2]
    d = env_directions(w, h).reshape(-1, 3)
    weight = (env_solid_angles(w, h).reshape(-1) * radiance.reshape(-1, 3).mean(axis=1))     # (T,) W m^-2 per cos
    back = d[:, 2] < -1e-6                                  # towards the array
    d, weight = d[back], weight[back]
    cos = -d[:, 2]                                          # against the normal -z
    panel = crosses_rectangle(points[:, None, :], d[None], extent)      # (P, T)
    window = panel & in_window(d, a)[None]
    lit = weight * cos
    e_all, e_win = panel @ lit, window @ lit
    return np.where(e_win > 0, e_all / np.maximum(e_win, 1e-30), 1.0)


def room_gain_at(radiance: np.ndarray, array, points: np.ndarray) -> np.ndarray:
    """(P,) float32 factor for the room's light at ``points`` (P, 3) (array frame, metres; NaN or z <= 0: unknown,
    factor 1): the ratio of the irradiance the whole panel passes to that the window passes, on a surface facing
    the array, found on a grid in front of the array and read trilinearly, within [1, :data:`MAX_GAIN`].

    Args:
        radiance: (h, w, 3) the light probe's map in the lens array's frame (Mitsuba's ``envmap`` convention).
        array: the lens array (its extent and angular half-width).
        points: (P, 3) where the light lands.
    """
    from scipy.interpolate import RegularGridInterpolator

    xmin, xmax, ymin, ymax = array.extent()
    gx, gy = np.linspace(xmin, xmax, GRID_XY), np.linspace(ymin, ymax, GRID_XY)
    X, Y, Z = np.meshgrid(gx, gy, GRID_DEPTHS, indexing="ij")
    grid = _gain_at(np.stack([X.ravel(), Y.ravel(), Z.ravel()], 1), np.asarray(radiance, np.float32),
                    (xmin, xmax, ymin, ymax), array.half_width).reshape(X.shape)
    look = RegularGridInterpolator((gx, gy, GRID_DEPTHS), grid, bounds_error=False, fill_value=None)
    p = np.asarray(points, float).reshape(-1, 3)
    z = p[:, 2]
    known = np.isfinite(z) & (z > 0) & np.all(np.isfinite(p[:, :2]), axis=1)
    pts = np.stack([np.clip(np.where(known, p[:, 0], xmin), xmin, xmax),
                    np.clip(np.where(known, p[:, 1], ymin), ymin, ymax),
                    np.clip(np.where(known, z, GRID_DEPTHS[0]), GRID_DEPTHS[0], GRID_DEPTHS[-1])], -1)
    gain = look(pts)
    return np.where(known, np.clip(gain, 1.0, MAX_GAIN), 1.0).astype(np.float32)


def steep_room_gain(radiance: np.ndarray, array, depth: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(K, V, U) factor for the room's light in each projected light field entry (see the module): the factor
    (:func:`room_gain_at`) where the entry's centre ray meets the measured depth.

    Args:
        radiance: (h, w, 3) the light probe's map in the lens array's frame (Mitsuba's ``envmap`` convention).
        array: the lens array (its extent, centres and angular half-width).
        depth: (K, V, U) the real scene's depth along each entry's centre ray, metres along the array's normal (NaN:
            unknown; the entry keeps factor 1).
        u, v: (U,), (V,) the entries' angular coordinates.

    Returns:
        (K, V, U) float32 in [1, :data:`MAX_GAIN`].
    """
    return room_gain_at(radiance, array, landing_points(array, depth, u, v)).reshape(np.shape(depth))


def landing_points(array, depth: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(K, V, U, 3) where each light field entry's centre ray meets the measured ``depth`` (K, V, U) (array frame,
    metres; NaN where the depth is unknown); ``u``, ``v``: the entries' angular coordinates."""
    c = array.centres                                                     # (K, 2)
    uu, vv = np.meshgrid(u, v)                                            # (V, U)
    z = np.asarray(depth, float)
    return np.stack([c[:, 0, None, None] + z * uu[None], c[:, 1, None, None] + z * vv[None], z], -1)
