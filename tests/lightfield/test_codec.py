"""Codecs: device image <-> light field, responses, and the camera/projector boundary."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from lftransfer.lightfield import (CameraModel, LensletCodec, LightField, LightFieldDecoder, LightFieldEncoder,
                                   ProjectorModel, ResponseCurve)
from lftransfer.optics import LensArray, LensletDevice

P = 0.0254
U = V = 12


def _rig(lattice, rotation=0.1, seed=0, width=200, height=150):
    arr = LensArray(lattice, 3, 4, P, P, rotation=rotation, offset=(0.004, -0.003))
    rng = np.random.default_rng(seed)
    dist = np.column_stack([rng.uniform(-0.1, 0.1, arr.K), rng.uniform(-0.03, 0.03, arr.K)])
    return arr, LensletDevice.fronto_parallel(arr, width, height, distortion=dist)


def _smooth(k, uv):
    """A smooth, lenslet-dependent test radiance, (..., 3) in about [0.2, 0.9]."""
    u, v = uv[..., 0], uv[..., 1]
    base = 0.5 + 0.15 * np.cos(3 * u) + 0.2 * v + 0.01 * k
    return np.stack([base, 0.8 * base + 0.1 * u, 0.6 + 0.2 * u * v + 0.0 * k], axis=-1)


def _smooth_lf(arr):
    lf = LightField.zeros(arr, U, V)
    uu, vv = np.meshgrid(lf.u, lf.v)
    uv = np.stack([uu, vv], -1)
    k = np.arange(arr.K)[:, None, None]
    lf.data[:] = _smooth(k, uv[None]) * lf.mask()[None, :, :, None]
    return lf


def _interior(lf, shrink=0.75):
    """(V, U) samples whose ideal offset is well inside the cell (also after distortion)."""
    uu, vv = np.meshgrid(lf.u, lf.v)
    f = lf.array.focal_length
    return lf.array.in_cell(np.stack([-f * uu, -f * vv], -1) / shrink)


@pytest.mark.parametrize("lattice", ["hex", "rect"])
def test_01_round_trip_of_a_smooth_lightfield(lattice):
    arr, dev = _rig(lattice)
    codec = LensletCodec(arr, dev, U, V)
    lf = _smooth_lf(arr)
    img = codec.lightfield_to_image(lf)
    assert img.shape == (150, 200, 3) and img.dtype == np.float32
    back = codec.image_to_lightfield(img)
    inner = _interior(lf)
    assert inner.sum() > 0.4 * inner.size
    np.testing.assert_allclose(back.data[:, inner], lf.data[:, inner], atol=0.003)
    # and all data samples, cell borders included, stay close (no cross-talk between lenslets)
    np.testing.assert_allclose(back.data, lf.data, atol=0.02)
    assert np.all(back.data[:, ~lf.mask()] == 0)


@pytest.mark.parametrize("lattice", ["hex", "rect"])
def test_02_forward_map_reads_the_pixel_of_each_ray(lattice):
    """An image painted with a known function of each pixel's ray decodes to that function at the samples."""
    arr, dev = _rig(lattice, seed=3)
    codec = LensletCodec(arr, dev, U, V)
    px = np.stack(np.meshgrid(np.arange(200.0), np.arange(150.0)), -1).reshape(-1, 2)
    k, d = dev.pixel_to_ray(arr, px)
    img = np.zeros((150 * 200, 3), np.float32)
    ok = k >= 0
    img[ok] = _smooth(k[ok], d[ok, :2] / d[ok, 2:])
    lf = codec.image_to_lightfield(img.reshape(150, 200, 3))
    truth = _smooth_lf(arr)
    inner = _interior(truth)
    np.testing.assert_allclose(lf.data[:, inner], truth.data[:, inner], atol=0.01)


@pytest.mark.parametrize("lattice", ["hex", "rect"])
def test_03_uniform_lightfield_gives_uniform_lenslet_images(lattice):
    arr, dev = _rig(lattice)
    codec = LensletCodec(arr, dev, U, V)
    lf = LightField.zeros(arr, U, V)
    lf.data[:] = 0.6 * lf.mask()[None, :, :, None]
    img = codec.lightfield_to_image(lf)
    covered = codec._inv_norm > 0
    assert covered.mean() > 0.4
    np.testing.assert_allclose(img[covered], 0.6, rtol=1e-5)
    np.testing.assert_array_equal(img[codec.pixel_lenslet < 0], 0)


@settings(max_examples=50, deadline=None)
@given(gamma=st.tuples(*[st.floats(0.3, 3.0)] * 3),
       x=hnp.arrays(np.float64, (7, 3), elements=st.floats(0.0, 1.0)))
def test_04_response_round_trip(gamma, x):
    r = ResponseCurve(gamma)
    code = r.encode(x)
    assert np.all((code >= 0) & (code <= 1))
    np.testing.assert_allclose(r.decode(code), x, atol=1e-9)
    np.testing.assert_allclose(r.encode(r.decode(x)), x, atol=1e-9)


def test_05_response_values_and_validation():
    r = ResponseCurve((2.0, 1.0, 0.5))
    np.testing.assert_allclose(r.encode(np.array([0.25, 0.25, 0.25])), [0.5, 0.25, 0.0625])
    np.testing.assert_allclose(r.decode(np.array([2.0, -1.0, 0.25])), [1.0, 0.0, 0.5])
    assert r.encode(np.zeros((2, 2, 3), np.float32)).dtype == np.float32
    with pytest.raises(ValueError, match="gamma"):
        ResponseCurve((1.0, 0.0, 1.0))
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        r.encode(np.zeros(4))


@pytest.mark.parametrize("lattice", ["hex", "rect"])
def test_06_encoder_then_emitted_reproduces_the_lightfield_image(lattice):
    arr, dev = _rig(lattice)
    gamma, max_rad = 2.2, 1.5
    prj = ProjectorModel(dev, bits=8, response=ResponseCurve((gamma,) * 3), max_radiance=max_rad)
    enc = LightFieldEncoder(arr, prj, U, V)
    lf = _smooth_lf(arr)
    image = enc(lf)
    assert image.dtype == np.uint8 and image.shape == (150, 200, 3)
    emitted = enc.emitted(image)
    target = enc.codec.lightfield_to_image(lf)
    step = gamma * max_rad / 255          # one code step in linear units, at the steepest part of the curve
    np.testing.assert_allclose(emitted, target, atol=step)
    assert np.abs(emitted - target).max() > 0   # quantisation is really there
    assert LightFieldEncoder(arr, ProjectorModel(dev, bits=10), U, V)(lf).dtype == np.uint16


@pytest.mark.parametrize("lattice", ["hex", "rect"])
def test_07_decoder_of_exposed_image_within_quantisation(lattice):
    arr, dev = _rig(lattice)
    rng = np.random.default_rng(2)
    vig = (0.7 + 0.3 * rng.random((150, 200))).astype(np.float32)
    gamma, exposure = 2.0, 0.8
    cam = CameraModel(dev, bits=12, response=ResponseCurve((gamma,) * 3), exposure=exposure, vignetting=vig)
    dec = LightFieldDecoder(arr, cam, U, V)
    codec = LensletCodec(arr, dev, U, V)
    lf = _smooth_lf(arr)
    img = codec.lightfield_to_image(lf)
    raw = dec.expose(img)
    assert raw.dtype == np.uint16 and raw.max() <= 4095
    out = dec(raw)
    target = codec.image_to_lightfield(img)
    step = gamma * 0.5 / 4095 / (exposure * vig.min())   # half a code step, in radiance
    np.testing.assert_allclose(out.data, target.data, atol=step * 1.01)
    np.testing.assert_allclose(out.data, lf.data, atol=0.03)


def test_08_validation():
    arr, dev = _rig("hex")
    codec = LensletCodec(arr, dev, U, V)
    with pytest.raises(ValueError, match=r"\(150, 200, 3\)"):
        codec.image_to_lightfield(np.zeros((150, 200), np.float32))
    with pytest.raises(ValueError, match="shape"):
        codec.lightfield_to_image(LightField.zeros(arr, U + 1, V))
    other = LensArray("rect", 3, 4, P, P)
    with pytest.raises(ValueError, match="lens array"):
        codec.lightfield_to_image(LightField.zeros(other, U, V))
    dec = LightFieldDecoder(arr, CameraModel(dev), U, V)
    with pytest.raises(ValueError, match="integer"):
        dec(np.zeros((150, 200, 3), np.float32))
    with pytest.raises(ValueError, match="vignetting"):
        CameraModel(dev, vignetting=np.ones((10, 10)))
    with pytest.raises(ValueError, match="bits"):
        ProjectorModel(dev, bits=0)
    with pytest.raises(ValueError, match=r"\(12, 2\)"):
        LensletCodec(arr, LensletDevice(200, 150, dev.homography, np.zeros((3, 2))), U, V)


@pytest.mark.parametrize("lattice", ["hex", "rect"])
def test_09_image_to_lightfield_as_a_sparse_matrix(lattice):
    """image_to_lightfield_matrix() is image_to_lightfield: the same taps and weights (to float32 rounding), masked
    samples 0, at most 4 taps a sample; a matrix with a tap moved by one pixel is not (the negative control)."""
    arr, dev = _rig(lattice)
    codec = LensletCodec(arr, dev, U, V)
    S = codec.image_to_lightfield_matrix()
    assert S.shape == (arr.K * V * U, 150 * 200) and np.all(np.diff(S.indptr) <= 4)
    img = np.random.default_rng(3).random((150, 200, 3)).astype(np.float32)
    want = codec.image_to_lightfield(img).data.reshape(-1, 3)
    got = S @ img.reshape(-1, 3)
    np.testing.assert_allclose(got, want, rtol=0, atol=2e-6)
    masked = ~np.tile(codec.mask.ravel(), arr.K)
    assert np.all(got[masked] == 0) and S[masked].nnz == 0
    shifted = S.copy()
    shifted.indices = np.minimum(shifted.indices + 1, 150 * 200 - 1)
    assert np.abs(shifted @ img.reshape(-1, 3) - want).max() > 0.01
