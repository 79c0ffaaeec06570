"""Lens array lattice: layout, cells, lenslet lookup and aperture sampling."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from lftransfer.optics import LensArray

P = 0.0254


def _arr(lattice="hex", **kw):
    kw = {"rows": 3, "cols": 4, "pitch": P, "focal_length": P, **kw}
    return LensArray(lattice, **kw)


def _shoelace(v):
    x, y = v[:, 0], v[:, 1]
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


@pytest.mark.parametrize("lattice", ["hex", "rect"])
def test_01_count_and_shapes(lattice):
    arr = _arr(lattice)
    assert arr.K == 12
    assert arr.centres.shape == (12, 2) and arr.centres.dtype == np.float64
    assert arr.centres3d.shape == (12, 3) and np.all(arr.centres3d[:, 2] == 0)
    assert arr.half_width == pytest.approx(0.5)


@pytest.mark.parametrize("lattice", ["hex", "rect"])
@pytest.mark.parametrize("rotation", [0.0, 0.3])
def test_02_nearest_neighbour_distance_is_pitch(lattice, rotation):
    arr = _arr(lattice, rows=5, cols=6, rotation=rotation)
    dist, _ = cKDTree(arr.centres).query(arr.centres, k=2)
    np.testing.assert_allclose(dist[:, 1], P, rtol=1e-12)


@pytest.mark.parametrize("lattice", ["hex", "rect"])
def test_03_row_major_row0_on_top(lattice):
    arr = _arr(lattice)
    c = arr.centres.reshape(3, 4, 2)
    assert np.all(np.diff(c[:, :, 1], axis=0) < 0)          # rows go down
    np.testing.assert_allclose(np.diff(c[:, :, 1], axis=1), 0)  # a row is horizontal
    np.testing.assert_allclose(np.diff(c[:, :, 0], axis=1), P)  # columns go right by one pitch
    np.testing.assert_allclose(arr.centres.mean(axis=0), 0, atol=1e-15)


def test_04_layouts_exact():
    rect = _arr("rect")
    np.testing.assert_allclose(rect.centres[0], [-1.5 * P, P])
    np.testing.assert_allclose(rect.centres[11], [1.5 * P, -P])
    hexa = _arr("hex")
    c = hexa.centres.reshape(3, 4, 2)
    np.testing.assert_allclose(c[0, 0, 1] - c[1, 0, 1], P * math.sqrt(3) / 2)
    np.testing.assert_allclose(c[1, 0, 0] - c[0, 0, 0], P / 2)   # odd rows shifted by +pitch/2
    np.testing.assert_allclose(c[2, 0, 0], c[0, 0, 0])


@pytest.mark.parametrize("lattice", ["hex", "rect"])
def test_05_rotation_and_offset_move_centres(lattice):
    base = _arr(lattice)
    th, off = 0.4, (0.01, -0.03)
    moved = _arr(lattice, rotation=th, offset=off)
    R = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    np.testing.assert_allclose(moved.centres, base.centres @ R.T + off, atol=1e-15)
    assert not np.allclose(moved.centres, base.centres)


@pytest.mark.parametrize("lattice", ["hex", "rect"])
@pytest.mark.parametrize("rotation", [0.0, 0.7])
def test_06_cell_vertices_area(lattice, rotation):
    arr = _arr(lattice, rotation=rotation)
    v = arr.cell_vertices()
    assert v.shape == ((6, 2) if lattice == "hex" else (4, 2))
    assert _shoelace(v) == pytest.approx(arr.cell_area, rel=1e-12)
    expected = P**2 * (math.sqrt(3) / 2 if lattice == "hex" else 1.0)
    assert arr.cell_area == pytest.approx(expected)
    assert arr.aperture_area == pytest.approx(expected)
    assert _arr(lattice, aperture="round").aperture_area == pytest.approx(math.pi * P**2 / 4)


def test_07_hex_cell_is_pointy_top():
    v = _arr("hex").cell_vertices()
    np.testing.assert_allclose(np.hypot(v[:, 0], v[:, 1]), P / math.sqrt(3))
    assert np.any(np.all(np.isclose(v, [0.0, P / math.sqrt(3)]), axis=1))  # a vertex straight up
    arr = _arr("hex")
    assert arr.in_cell(np.array([0.49 * P, 0.0])) and not arr.in_cell(np.array([0.51 * P, 0.0]))
    assert arr.in_cell(np.array([0.0, 0.57 * P])) and not arr.in_cell(np.array([0.0, 0.58 * P]))


@pytest.mark.parametrize("lattice", ["hex", "rect"])
@pytest.mark.parametrize("rotation", [0.0, 0.5])
def test_08_lenslet_at(lattice, rotation):
    arr = _arr(lattice, rotation=rotation, offset=(0.02, 0.01))
    np.testing.assert_array_equal(arr.lenslet_at(arr.centres), np.arange(arr.K))
    # just inside each vertex of every cell
    pts = arr.centres[:, None, :] + 0.98 * arr.cell_vertices()[None]
    np.testing.assert_array_equal(arr.lenslet_at(pts), np.repeat(np.arange(arr.K)[:, None], len(arr.cell_vertices()), 1))
    xmin, xmax, ymin, ymax = arr.extent()
    outside = np.array([[xmax + 0.001, 0.02], [xmin - 0.01, ymin - 0.01], [0.02, ymax + 1.0], [np.nan, 0.0]])
    np.testing.assert_array_equal(arr.lenslet_at(outside), -1)
    assert arr.lenslet_at(np.zeros((2, 3, 2))).shape == (2, 3)


def test_09_extent_rect():
    xmin, xmax, ymin, ymax = _arr("rect").extent()
    assert (xmin, xmax, ymin, ymax) == pytest.approx((-2 * P, 2 * P, -1.5 * P, 1.5 * P))


@pytest.mark.parametrize("lattice", ["hex", "rect"])
@pytest.mark.parametrize("aperture", ["cell", "round"])
def test_10_sample_aperture(lattice, aperture):
    arr = _arr(lattice, aperture=aperture, rotation=0.2)
    s = arr.sample_aperture(512, seed=3)
    assert s.shape == (512, 2)
    assert np.all(arr.in_aperture(s))
    np.testing.assert_allclose(s.mean(axis=0), 0, atol=0.01 * P)
    np.testing.assert_array_equal(s, arr.sample_aperture(512, seed=3))
    assert not np.allclose(s, arr.sample_aperture(512, seed=4))
    # well stratified: the fraction in the right half is close to 1/2, in the inner half-size copy ~ 1/4
    assert abs(np.mean(s @ [1.0, 0.0] > 0) - 0.5) < 0.02
    assert abs(np.mean(arr.in_aperture(2.0 * s)) - 0.25) < 0.02
    assert len(arr.sample_aperture(0)) == 0


def test_11_round_aperture_is_a_disk():
    arr = _arr("hex", aperture="round")
    assert arr.in_aperture(np.array([0.0, 0.499 * P])) and not arr.in_aperture(np.array([0.0, 0.51 * P]))
    assert arr.in_cell(np.array([0.0, 0.51 * P]))


@pytest.mark.parametrize("kwargs, match", [
    ({"lattice": "tri"}, "lattice"),
    ({"rows": 0}, "rows"),
    ({"cols": 2.5}, "cols"),
    ({"pitch": -1.0}, "pitch"),
    ({"focal_length": 0.0}, "focal_length"),
    ({"aperture": "square"}, "aperture"),
    ({"offset": (1.0,)}, "offset"),
])
def test_12_validation(kwargs, match):
    base = {"lattice": "hex", "rows": 2, "cols": 2, "pitch": P, "focal_length": P}
    with pytest.raises(ValueError, match=match):
        LensArray(**{**base, **kwargs})


def test_13_hashable_and_equal():
    assert _arr("hex") == _arr("hex", offset=[0, 0])
    assert hash(_arr("hex")) == hash(_arr("hex"))
    assert _arr("hex") != _arr("rect")


@pytest.mark.parametrize("lattice", ["hex", "rect"])
def test_14_interpolation_is_linear_and_keeps_each_lenslets_flux(lattice):
    """Across-lenslet interpolation: each centre reads itself, a linear function is rebuilt exactly inside the
    lattice, every interior lenslet's hat integrates to its cell area, points outside every cell read nothing."""
    a = _arr(lattice, rows=8, cols=9, rotation=0.2, offset=(0.003, -0.002))
    idx, w = a.interpolation(a.centres)
    np.testing.assert_allclose((w * (idx == np.arange(a.K)[:, None])).sum(1), 1.0, atol=1e-9)
    # a linear function of position, sampled at the centres, read anywhere inside the hull of the centres
    f = a.centres @ np.array([3.0, -2.0]) + 0.5
    rng = np.random.default_rng(1)
    inside = a.centres[rng.integers(0, a.K, 4000)] * 0.7               # well inside the lattice
    idx, w = a.interpolation(inside)
    np.testing.assert_allclose(w.sum(1), 1.0, atol=1e-12)
    assert (w >= 0).all() and (idx >= 0).all()
    np.testing.assert_allclose((w * f[idx]).sum(1), inside @ np.array([3.0, -2.0]) + 0.5, atol=1e-12)
    # hat integrals, by a midpoint rule on a fine grid over the whole array
    xmin, xmax, ymin, ymax = a.extent()
    n = 1500
    gx = xmin + (np.arange(n) + 0.5) * (xmax - xmin) / n
    gy = ymin + (np.arange(n) + 0.5) * (ymax - ymin) / n
    pts = np.stack(np.meshgrid(gx, gy), -1).reshape(-1, 2)
    idx, w = a.interpolation(pts)
    hat = np.bincount(idx[idx >= 0], w[idx >= 0], minlength=a.K) * (xmax - xmin) * (ymax - ymin) / n**2
    rows, cols = np.divmod(np.arange(a.K), a.cols)
    interior = (rows > 0) & (rows < a.rows - 1) & (cols > 0) & (cols < a.cols - 1)
    np.testing.assert_allclose(hat[interior] / a.cell_area, 1.0, atol=2e-3)
    far = a.interpolation(np.array([[1.0, 1.0]]))
    assert (far[0] == -1).all() and (far[1] == 0).all()
