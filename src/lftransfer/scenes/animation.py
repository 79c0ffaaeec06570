"""Keyframe interpolation of object transforms (docs/architecture.md, "The live loop": objects move by keyframed
transforms).

An object's ``translate``, ``rotate_deg`` and ``scale`` are keyed at increasing times; between keys each
component follows one of two curves:

- ``"linear"``: piecewise linear (constant velocity between keys, a corner at each key);
- ``"smooth"``: a cubic Hermite curve through the keys with Catmull-Rom tangents inside and zero tangents at the
  first and last key (it starts and stops gently; with two keys it is the smoothstep ease-in/ease-out).

Before the first key an object holds the first key's pose, after the last key the last one's. Euler angles are
interpolated component by component, as they are written in the scene file.

Example:
    >>> import numpy as np
    >>> interpolate(np.array([0.0, 2.0]), np.array([[0.0], [1.0]]), 1.0, "linear")
    array([0.5])
"""

from __future__ import annotations

from typing import Literal

import numpy as np

__all__ = ["INTERPOLATIONS", "Interpolation", "frame_times", "interpolate"]

Interpolation = Literal["linear", "smooth"]
INTERPOLATIONS: tuple[str, ...] = ("linear", "smooth")


def interpolate(times: np.ndarray, values: np.ndarray, t: float, mode: Interpolation = "linear") -> np.ndarray:
    """The keyed quantity at time ``t``.

    Args:
        times: (K,) strictly increasing key times, seconds (K >= 1).
        values: (K, D) the quantity at each key.
        t: the time, seconds.
        mode: ``"linear"`` or ``"smooth"`` (module docstring).

    Returns:
        (D,) float64 value at ``t``.
    """
    times = np.asarray(times, np.float64)
    values = np.asarray(values, np.float64)
    if mode not in INTERPOLATIONS:
        raise ValueError(f"interpolation must be one of {INTERPOLATIONS}, got {mode!r}")
    if times.ndim != 1 or values.shape[:1] != times.shape or len(times) == 0:
        raise ValueError(f"times (K,) and values (K, D) must agree, got {times.shape} and {values.shape}")
    if np.any(np.diff(times) <= 0):
        raise ValueError(f"key times must increase strictly, got {times.tolist()}")
    if t <= times[0] or len(times) == 1:
        return values[0].copy()
    if t >= times[-1]:
        return values[-1].copy()
    i = int(np.searchsorted(times, t, side="right")) - 1          # times[i] <= t < times[i + 1]
    t0, t1 = times[i], times[i + 1]
    h = t1 - t0
    s = (t - t0) / h
    p0, p1 = values[i], values[i + 1]
    if mode == "linear":
        return (1 - s) * p0 + s * p1

    def tangent(j: int) -> np.ndarray:                               # d value / d t at key j
        if j == 0 or j == len(times) - 1:
            return np.zeros_like(values[j])
        return (values[j + 1] - values[j - 1]) / (times[j + 1] - times[j - 1])

    m0, m1 = tangent(i) * h, tangent(i + 1) * h
    s2, s3 = s * s, s * s * s
    return ((2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * m0
            + (-2 * s3 + 3 * s2) * p1 + (s3 - s2) * m1)


def frame_times(duration_s: float, fps: float) -> np.ndarray:
    """Times of the frames of a sequence: ``i / fps`` for every i with ``i / fps < duration_s`` (at least one).

    Args:
        duration_s: length of the sequence, seconds (> 0).
        fps: frames per second (> 0).

    Returns:
        (F,) float64 seconds, F = ceil(duration_s * fps).
    """
    if not (duration_s > 0 and fps > 0):
        raise ValueError(f"duration_s and fps must be > 0, got {duration_s} and {fps}")
    n = max(1, int(np.ceil(duration_s * fps - 1e-9)))
    return np.arange(n, dtype=np.float64) / fps
