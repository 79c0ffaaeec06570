"""Lenslet device: pixel <-> ray maps, homography and distortion."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lftransfer.optics import LensArray, LensletDevice

P = 0.0254


def _arr(lattice="hex", **kw):
    return LensArray(lattice, 3, 4, P, P, **kw)


def _perturbed_device(arr, seed, k_scale):
    """A device with random per-lenslet distortion and a non-trivial (projective) homography."""
    rng = np.random.default_rng(seed)
    base = LensletDevice.fronto_parallel(arr, 200, 150)
    dist = np.column_stack([rng.uniform(-0.15, 0.15, arr.K), rng.uniform(-0.05, 0.05, arr.K)]) * k_scale
    warp = np.array([[1.0 + rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), rng.uniform(-5, 5)],
                     [rng.uniform(-0.05, 0.05), 1.0 + rng.uniform(-0.05, 0.05), rng.uniform(-5, 5)],
                     [rng.uniform(-3e-4, 3e-4), rng.uniform(-3e-4, 3e-4), 1.0]])
    return LensletDevice(200, 150, warp @ base.homography, dist)


@settings(max_examples=25, deadline=None)
@given(lattice=st.sampled_from(["hex", "rect"]), rotation=st.floats(-math.pi, math.pi),
       seed=st.integers(0, 2**31 - 1), k_scale=st.floats(0.2, 1.0))
def test_01_pixel_ray_pixel_round_trip(lattice, rotation, seed, k_scale):
    arr = _arr(lattice, rotation=rotation, offset=(0.003, -0.002))
    dev = _perturbed_device(arr, seed, k_scale)
    assert np.any(dev.distortion != 0)
    px = np.random.default_rng(seed + 1).uniform([-0.5, -0.5], [199.5, 149.5], size=(400, 2))
    k, d = dev.pixel_to_ray(arr, px)
    inside = k >= 0
    assert inside.sum() > 50
    np.testing.assert_allclose(np.linalg.norm(d[inside], axis=1), 1.0, rtol=1e-12)
    assert np.all(d[inside, 2] > 0)
    back = dev.ray_to_pixel(arr, k[inside], d[inside])
    np.testing.assert_allclose(back, px[inside], atol=1e-7)


@pytest.mark.parametrize("lattice", ["hex", "rect"])
def test_02_centre_pixel_looks_along_the_axis(lattice):
    arr = _arr(lattice, rotation=0.3)
    dev = _perturbed_device(arr, 5, 1.0)
    c = np.column_stack([arr.centres, np.ones(arr.K)]) @ dev.homography.T
    px = c[:, :2] / c[:, 2:]
    k, d = dev.pixel_to_ray(arr, px)
    np.testing.assert_array_equal(k, np.arange(arr.K))
    np.testing.assert_allclose(d, np.tile([0.0, 0.0, 1.0], (arr.K, 1)), atol=1e-12)


def test_03_fronto_parallel_geometry():
    arr = _arr("rect")
    dev = LensletDevice.fronto_parallel(arr, 200, 150, margin=0.0)
    H = dev.homography
    xmin, xmax, ymin, ymax = arr.extent()
    corners = np.array([[xmin, ymax, 1.0], [xmax, ymin, 1.0]]) @ H.T
    # the 4 x 3 pitch array fills 200 x 150 exactly: top-left -> (-0.5, -0.5), bottom-right -> (199.5, 149.5)
    np.testing.assert_allclose(corners[:, :2], [[-0.5, -0.5], [199.5, 149.5]], atol=1e-9)
    assert H[0, 0] == pytest.approx(-H[1, 1]) and H[0, 0] > 0          # square pixels, +y is image up
    np.testing.assert_array_equal(dev.distortion, np.zeros((arr.K, 2)))


def test_04_ideal_offsets_map_to_expected_directions():
    arr = _arr("hex")
    dev = LensletDevice.fronto_parallel(arr, 400, 300)
    o = np.array([[0.2, 0.1], [-0.3, 0.25], [0.0, -0.4]]) * P
    q = arr.centres[5] + o
    h = np.column_stack([q, np.ones(3)]) @ dev.homography.T
    k, d = dev.pixel_to_ray(arr, h[:, :2] / h[:, 2:])
    expected = np.column_stack([-o, np.full(3, P)])
    np.testing.assert_array_equal(k, 5)
    np.testing.assert_allclose(d, expected / np.linalg.norm(expected, axis=1, keepdims=True), atol=1e-12)


def test_05_distortion_follows_opencv_radial_model():
    arr = _arr("rect")
    dist = np.zeros((arr.K, 2))
    dist[3] = [0.1, -0.03]
    dev = LensletDevice.fronto_parallel(arr, 400, 300, distortion=dist)
    uv = np.array([[0.2, -0.1], [0.3, 0.35]])
    d = np.column_stack([uv, np.ones(2)])
    px = dev.ray_to_pixel(arr, np.array([3, 3]), d)
    xn = -uv
    r2 = np.sum(xn**2, axis=1, keepdims=True)
    q = arr.centres[3] + P * xn * (1 + 0.1 * r2 - 0.03 * r2**2)
    h = np.column_stack([q, np.ones(2)]) @ dev.homography.T
    np.testing.assert_allclose(px, h[:, :2] / h[:, 2:], atol=1e-9)
    ideal = LensletDevice.fronto_parallel(arr, 400, 300).ray_to_pixel(arr, np.array([3, 3]), d)
    assert np.max(np.abs(px - ideal)) > 0.5                       # the distortion moves the pixels visibly


def test_06_pixels_off_the_array():
    arr = _arr("hex")
    dev = LensletDevice.fronto_parallel(arr, 200, 150, margin=0.2)
    k, d = dev.pixel_to_ray(arr, np.array([[0.0, 0.0], [199.0, 149.0], [99.5, 74.5]]))
    assert list(k[:2]) == [-1, -1] and k[2] >= 0
    assert np.all(np.isnan(d[:2])) and np.all(np.isfinite(d[2]))
    out = dev.ray_to_pixel(arr, np.array([-1, 0, 0]), np.array([[0, 0, 1.0], [0, 0, -1.0], [0, 0, 1.0]]))
    assert np.all(np.isnan(out[:2])) and np.all(np.isfinite(out[2]))


def test_07_validation():
    arr = _arr("hex")
    H = np.eye(3)
    with pytest.raises(ValueError, match="homography"):
        LensletDevice(10, 10, np.eye(2), np.zeros((arr.K, 2)))
    with pytest.raises(ValueError, match="distortion"):
        LensletDevice(10, 10, H, np.zeros((arr.K, 3)))
    with pytest.raises(ValueError, match="width"):
        LensletDevice(0, 10, H, np.zeros((arr.K, 2)))
    dev = LensletDevice(10, 10, H, np.zeros((5, 2)))
    with pytest.raises(ValueError, match=r"\(12, 2\)"):
        dev.pixel_to_ray(arr, np.zeros((1, 2)))
    dev = LensletDevice(10, 10, H, np.zeros((arr.K, 2)))
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        dev.pixel_to_ray(arr, np.zeros((1, 3)))
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        dev.ray_to_pixel(arr, np.zeros(2, int), np.zeros((3, 3)))
