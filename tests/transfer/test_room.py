"""The room's steep light on the real side, sent at the lenslets' angles (lftransfer.transfer.room).

What each test shows:
- test_01: in a uniform room, a surface facing an array much wider than its distance sees the panel over its whole
  half of the sky (irradiance pi L) and the lenslets' window over 4 X of it, X = (a / sqrt(1 + a^2))
  atan(a / sqrt(1 + a^2)) (0.752 for a = 0.5): the factor is pi / (4 X) = 4.18, to 2 %. Far from a small array
  the whole panel lies inside the window: factor 1. In between it falls with the distance.
- test_02: per light field entry the factor is read where its centre ray lands at the measured depth; entries
  without a depth keep factor 1, and no factor exceeds MAX_GAIN.
- test_03: per measured point (the solve's targets) the factor is the one an entry landing there gets: the same
  function read at the same point; a point with no depth (NaN) or behind the array keeps factor 1.
"""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.optics import LensArray
from lftransfer.transfer.room import MAX_GAIN, _gain_at, room_gain_at, steep_room_gain


def test_01_the_factor_against_the_analytic_one():
    a = 0.5
    x = a / np.sqrt(1 + a * a) * np.arctan(a / np.sqrt(1 + a * a))
    room = np.ones((256, 512, 3), np.float32)
    near = _gain_at(np.array([[0.0, 0.0, 0.05]]), room, (-100, 100, -100, 100), a)[0]
    assert near == pytest.approx(np.pi / (4 * x), rel=0.02), (near, np.pi / (4 * x))
    far = _gain_at(np.array([[0.0, 0.0, 1.0]]), room, (-0.15, 0.15, -0.11, 0.11), a)[0]
    assert far == pytest.approx(1.0)
    ladder = _gain_at(np.array([[0.0, 0.0, z] for z in (0.02, 0.08, 0.2, 0.5)]), room, (-0.15, 0.15, -0.11, 0.11), a)
    assert np.all(np.diff(ladder) < 0) and ladder[0] > 3.5


def test_02_per_entry_where_it_lands():
    array = LensArray(lattice="rect", rows=3, cols=4, pitch=0.0254, focal_length=0.0254)
    U = V = 4
    u = v = (np.arange(U) + 0.5) / U * 2 * array.half_width - array.half_width
    depth = np.full((array.K, V, U), 0.03)
    depth[0] = np.nan
    gain = steep_room_gain(np.ones((64, 128, 3), np.float32), array, depth, u, v)
    assert gain.shape == (array.K, V, U) and gain.dtype == np.float32
    assert np.all(gain[0] == 1.0) and np.all(gain[1:] > 1.0) and gain.max() <= MAX_GAIN
    deeper = steep_room_gain(np.ones((64, 128, 3), np.float32), array, np.full((array.K, V, U), 0.3), u, v)
    assert np.all(deeper[1:] < gain[1:])


def test_03_per_point_as_per_entry_landing_there():
    array = LensArray(lattice="rect", rows=3, cols=4, pitch=0.0254, focal_length=0.0254)
    U = V = 4
    u = v = (np.arange(U) + 0.5) / U * 2 * array.half_width - array.half_width
    rng = np.random.default_rng(0)
    depth = rng.uniform(0.01, 0.2, (array.K, V, U))
    room = rng.uniform(0.5, 2.0, (64, 128, 3)).astype(np.float32)
    per_entry = steep_room_gain(room, array, depth, u, v)
    uu, vv = np.meshgrid(u, v)
    points = np.stack([array.centres[:, 0, None, None] + depth * uu, array.centres[:, 1, None, None] + depth * vv,
                       depth], -1).reshape(-1, 3)
    np.testing.assert_array_equal(room_gain_at(room, array, points), per_entry.ravel())
    unknown = room_gain_at(room, array, np.array([[0.0, 0.0, np.nan], [0.0, 0.0, -0.1], [np.nan, 0.0, 0.05]]))
    np.testing.assert_array_equal(unknown, [1.0, 1.0, 1.0])
