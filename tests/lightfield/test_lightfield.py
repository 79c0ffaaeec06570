"""LightField: grid, mask, radiometry, lookup and arithmetic."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import dblquad

from lftransfer.lightfield import LightField
from lftransfer.optics import LensArray

P = 0.0254


def _arr(lattice="hex", f=P, **kw):
    return LensArray(lattice, 3, 4, P, f, **kw)


def _projected_solid_angle_square(a):
    """Analytic integral of du dv / (1 + u^2 + v^2)^2 over [-a, a]^2 (form factor of a parallel rectangle)."""
    s = math.sqrt(1 + a * a)
    return 4 * 2 * (a / (2 * s)) * math.atan(a / s)


def test_01_grid_and_directions():
    lf = LightField.zeros(_arr(), 8, 6)
    assert (lf.K, lf.V, lf.U) == (12, 6, 8) and lf.data.dtype == np.float32
    np.testing.assert_allclose(lf.u, -0.5 + (np.arange(8) + 0.5) / 8)
    np.testing.assert_allclose(lf.v, -0.5 + (np.arange(6) + 0.5) / 6)
    d = lf.directions()
    assert d.shape == (6, 8, 3)
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1)
    np.testing.assert_allclose(d[..., 0] / d[..., 2], np.broadcast_to(lf.u, (6, 8)))
    np.testing.assert_allclose(d[..., 1] / d[..., 2], np.broadcast_to(lf.v[:, None], (6, 8)))


def test_02_hex_mask_fraction_matches_analytic():
    lf = LightField.zeros(_arr("hex"), 128, 128)
    # the [-1/2, 1/2]^2 square minus four corner triangles outside the pointy-top hexagon of inradius 1/2
    expected = 2 - 2 / math.sqrt(3)
    assert lf.mask().mean() == pytest.approx(expected, abs=0.003)
    m = lf.mask()
    assert m[64, :].all() and not m[0, 0] and not m[-1, -1] and m[0, 64]   # full rows mid-height, corners cut


def test_03_mask_rotates_with_the_lattice():
    m0 = LightField.zeros(_arr("hex"), 32, 32).mask()
    m90 = LightField.zeros(_arr("hex", rotation=math.pi / 2), 32, 32).mask()
    np.testing.assert_array_equal(m90, m0.T)


@pytest.mark.parametrize("f_over_p", [1.0, 2.0])
def test_04_power_of_uniform_rect_field(f_over_p):
    arr = _arr("rect", f=P * f_over_p)
    lf = LightField.zeros(arr, 64, 64)
    assert lf.mask().all()
    L = np.array([1.0, 2.0, 0.5], np.float32)
    lf.data[:] = L
    a = arr.half_width
    integral = _projected_solid_angle_square(a)
    numeric, _ = dblquad(lambda v, u: (1 + u * u + v * v) ** -2, -a, a, -a, a)
    assert integral == pytest.approx(numeric, rel=1e-9)
    expected = arr.K * arr.cell_area * L * integral
    np.testing.assert_allclose(lf.power(), expected, rtol=1e-4)
    np.testing.assert_allclose(lf.solid_angle_weights().sum(), integral, rtol=1e-4)


def test_05_power_uses_the_aperture_area():
    cell = LightField.zeros(_arr("hex"), 16, 16)
    cell.data[:] = 1.0
    round_ = LightField(cell.data.copy(), _arr("hex", aperture="round"))
    ratio = round_.power() / cell.power()
    np.testing.assert_allclose(ratio, math.pi / (2 * math.sqrt(3)), rtol=1e-12)


def test_06_lookup():
    arr = _arr("hex")
    lf = LightField.zeros(arr, 12, 12)
    rng = np.random.default_rng(0)
    lf.data[:] = rng.random(lf.data.shape, dtype=np.float32) * lf.mask()[None, :, :, None]
    # at the grid samples: the data
    d = np.tile(lf.directions().reshape(-1, 3), (arr.K, 1))
    k = np.repeat(np.arange(arr.K), 144)
    np.testing.assert_allclose(lf.lookup(k, d), lf.data.reshape(-1, 3), atol=1e-6)
    # halfway between two data samples of a row: their mean
    j, i = 6, 3
    dm = np.array([(lf.u[i] + lf.u[i + 1]) / 2, lf.v[j], 1.0])
    np.testing.assert_allclose(lf.lookup(np.array([2]), dm[None])[0], lf.data[2, j, i:i + 2].mean(0), atol=1e-5)
    # zero for no lenslet, steep rays and backward rays
    bad = lf.lookup(np.array([-1, 0, 0]), np.array([[0, 0, 1.0], [0.6, 0, 1.0], [0, 0, -1.0]]))
    np.testing.assert_array_equal(bad, 0)


def test_07_lookup_of_uniform_field_is_uniform_inside_the_cell():
    arr = _arr("hex")
    lf = LightField.zeros(arr, 10, 10)
    lf.data[:] = 0.7 * lf.mask()[None, :, :, None]
    uv = np.random.default_rng(1).uniform(-0.5, 0.5, (2000, 2))
    inside = arr.in_cell(-arr.focal_length * uv)
    out = lf.lookup(np.full(2000, 4), np.column_stack([uv, np.ones(2000)]))
    np.testing.assert_allclose(out[inside], 0.7, rtol=1e-5)
    np.testing.assert_array_equal(out[~inside], 0)


def test_08_arithmetic():
    arr = _arr("hex")
    a = LightField.zeros(arr, 4, 4)
    a.data[:] = 1.0
    b = a * 3
    assert isinstance(b, LightField)
    np.testing.assert_array_equal((a + b).data, 4)
    np.testing.assert_array_equal((b - a).data, 2)
    np.testing.assert_array_equal((2.0 * a).data, 2)
    np.testing.assert_array_equal((b / 2).data, 1.5)
    np.testing.assert_array_equal((-a).data, -1)
    np.testing.assert_array_equal(sum([a, a, b]).data, 5)
    assert (a * 2).data.dtype == np.float32
    c = a.copy()
    c.data[:] = 9
    assert np.all(a.data == 1)
    with pytest.raises(ValueError, match="lens arrays"):
        a + LightField.zeros(_arr("rect"), 4, 4)
    with pytest.raises(ValueError, match="shape"):
        a - LightField.zeros(arr, 4, 5)
    with pytest.raises(TypeError):
        a * a


def test_09_validation():
    arr = _arr("hex")
    with pytest.raises(ValueError, match=r"\(K, V, U, 3\)"):
        LightField(np.zeros((12, 4, 4)), arr)
    with pytest.raises(ValueError, match="K = 12"):
        LightField(np.zeros((11, 4, 4, 3)), arr)
    assert LightField(np.zeros((12, 2, 2, 3)), arr).data.dtype == np.float32
