"""The fast device codec paths (lookup tables, patch gather) equal the plain float reference, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lftransfer.lightfield import (CameraModel, LensletCodec, LightField, LightFieldDecoder, LightFieldEncoder,
                                   ProjectorModel, ResponseCurve)
from lftransfer.lightfield.codec import _PatchSampler, _Remap
from lftransfer.lightfield.devices import _LinearCodes, _Quantiser
from lftransfer.optics import LensArray, LensletDevice

P = 0.0254
U = V = 12


def _rig(lattice="hex", seed=0, width=200, height=150, shift=0.0):
    """Array and device; ``shift`` (pixels) moves the image so that lenslets are cut by its border."""
    arr = LensArray(lattice, 3, 4, P, P, rotation=0.1, offset=(0.004, -0.003))
    rng = np.random.default_rng(seed)
    dist = np.column_stack([rng.uniform(-0.1, 0.1, arr.K), rng.uniform(-0.03, 0.03, arr.K)])
    dev = LensletDevice.fronto_parallel(arr, width, height, distortion=dist)
    if shift:
        move = np.array([[1.0, 0.0, shift], [0.0, 1.0, -0.7 * shift], [0.0, 0.0, 1.0]])
        dev = LensletDevice(width, height, move @ dev.homography, dev.distortion)
    return arr, dev


# ---- the reference implementation (the plain float path the fast paths replace)
def _ref_radiance_image(camera: CameraModel, raw: np.ndarray) -> np.ndarray:
    vig = np.ones((camera.device.height, camera.device.width), np.float32) \
        if camera.vignetting is None else camera.vignetting
    gain = camera.exposure * vig.astype(np.float64)
    inv_gain = np.where(gain > 0, 1.0 / np.where(gain > 0, gain, 1.0), 0.0).astype(np.float32)
    code = raw.astype(np.float32) / np.float32(camera.levels)
    linear = camera.response.decode(code)
    return (linear * inv_gain[..., None]).astype(np.float32, copy=False)


def _ref_lightfield_to_image(codec: LensletCodec, lf: LightField) -> np.ndarray:
    src = (lf.data * codec.mask[None, :, :, None]).reshape(codec.array.K * codec.V, codec.U, 3)
    img = _Remap(codec.inv_map_x, codec.inv_map_y, (codec.array.K * codec.V, codec.U))(src)
    return (img * codec._inv_norm[..., None]).astype(np.float32, copy=False)


def _ref_encode(projector: ProjectorModel, codec: LensletCodec, lf: LightField) -> np.ndarray:
    img = _ref_lightfield_to_image(codec, lf)
    linear = np.clip(img / np.float32(projector.max_radiance), 0.0, 1.0)
    code = projector.response.encode(linear)
    return np.round(code * np.float32(projector.levels)).astype(projector.dtype)


def _ref_quantise(projector: ProjectorModel, img: np.ndarray) -> np.ndarray:
    linear = np.clip(img / np.float32(projector.max_radiance), 0.0, 1.0)
    code = projector.response.encode(linear)
    return np.round(code * np.float32(projector.levels)).astype(np.int64)


def _lf(arr, rng, scale=1.0, lo=0.0):
    lf = LightField.zeros(arr, U, V)
    lf.data[:] = (lo + (1.0 - lo) * rng.random(lf.data.shape)) * scale   # masked samples too: must be ignored
    return lf


# ---- decoder
@settings(max_examples=30, deadline=None)
@given(gamma=st.tuples(*[st.floats(0.3, 3.0)] * 3), bits=st.integers(1, 16))
def test_01_decode_table_equals_decode_for_every_code(gamma, bits):
    r = ResponseCurve(gamma)
    levels = 2**bits - 1
    table = r.decode_table(levels)
    codes = np.arange(65536)
    expected = r.decode(np.repeat(codes[:, None], 3, 1).astype(np.float32) / np.float32(levels))
    assert table.shape == (3, 65536) and table.dtype == np.float32
    np.testing.assert_array_equal(table.T, expected)


@pytest.mark.parametrize("bits", [8, 12, 16])
def test_02_linear_codes_equal_the_table(bits):
    arr, dev = _rig()
    cam = CameraModel(dev, bits=bits, exposure=0.37)
    dec = LightFieldDecoder(arr, cam, U, V)
    assert dec._linear is not None   # linear response, no vignetting: arithmetic instead of a gather
    codes = np.arange(65536, dtype=np.uint16)
    np.testing.assert_array_equal(dec._linear(codes), dec._table[0])
    assert _LinearCodes.build(CameraModel(dev, response=ResponseCurve((1.0, 2.0, 1.0))), dec._table,
                              np.float32(1.0)) is None


def _cameras(dev, rng):
    vig = (0.5 + 0.5 * rng.random((dev.height, dev.width))).astype(np.float32)
    vig[0, :7] = 0.0                                    # dead pixels: radiance 0
    return [
        CameraModel(dev, bits=12, exposure=0.25),                                            # linear (fig4)
        CameraModel(dev, bits=12, response=ResponseCurve((2.2,) * 3), exposure=0.8),        # one gamma
        CameraModel(dev, bits=10, response=ResponseCurve((2.2, 1.0, 0.45)), exposure=1.3, vignetting=vig),
        CameraModel(dev, bits=16, response=ResponseCurve((1.0,) * 3), vignetting=vig),
        CameraModel(dev, bits=8, response=ResponseCurve((1.8,) * 3), exposure=2.0),
    ]


@pytest.mark.parametrize("lattice", ["hex", "rect"])
@pytest.mark.parametrize("shift", [0.0, 17.5])    # lenslets cut by the image border
def test_03_decoder_equals_the_float_reference(lattice, shift):
    arr, dev = _rig(lattice, seed=4, shift=shift)
    rng = np.random.default_rng(5)
    for cam in _cameras(dev, rng):
        dec = LightFieldDecoder(arr, cam, U, V)
        assert dec._patches is not None
        raw = rng.integers(0, cam.levels + 1, (dev.height, dev.width, 3)).astype(np.uint16)
        if cam.bits < 16:
            raw[5, :9] = cam.levels + 3                  # out-of-range codes clip like the float path
        ref_img = _ref_radiance_image(cam, raw)
        np.testing.assert_array_equal(dec.radiance_image(raw), ref_img)
        ref = dec.codec.image_to_lightfield(ref_img)
        out = dec(raw)
        assert out.data.dtype == np.float32 and out.data.shape == ref.data.shape
        np.testing.assert_array_equal(out.data, ref.data)


def test_04_decoder_other_integer_dtypes_and_fallback():
    arr, dev = _rig()
    rng = np.random.default_rng(6)
    cam = CameraModel(dev, bits=8, response=ResponseCurve((2.0, 2.2, 2.4)), exposure=0.5)
    dec = LightFieldDecoder(arr, cam, U, V)
    raw8 = rng.integers(0, 256, (dev.height, dev.width, 3)).astype(np.uint8)
    ref = dec.codec.image_to_lightfield(_ref_radiance_image(cam, raw8))
    np.testing.assert_array_equal(dec(raw8).data, ref.data)
    raw32 = raw8.astype(np.int32)
    raw32[0, 0] = -5
    raw32[1, 1] = 1000
    ref = dec.codec.image_to_lightfield(_ref_radiance_image(cam, raw32))
    np.testing.assert_array_equal(dec(raw32).data, ref.data)
    np.testing.assert_array_equal(dec.radiance_image(raw32), _ref_radiance_image(cam, raw32))
    dec._patches = None                                  # the path for images too large for cv2.remap
    np.testing.assert_array_equal(dec(raw32).data, ref.data)


def test_05_patch_sampler_equals_the_remap():
    """gather + interpolate reproduces cv2.remap bit for bit, samples off and across the border included."""
    rng = np.random.default_rng(7)
    H, W = 40, 50
    mx = rng.uniform(-3, W + 2, (30, 20)).astype(np.float32)
    my = rng.uniform(-3, H + 2, (30, 20)).astype(np.float32)
    mx[0, :5], my[0, :5] = -1.0e4, -1.0e4
    mx[1, :3] = np.float32(W - 1) + np.float32([0.0, 0.5, 0.999])
    remap = _Remap(mx, my, (H, W))
    assert _PatchSampler.fits(remap)
    ps = _PatchSampler(remap)
    src = (rng.random((H, W, 3)) * 10 - 2).astype(np.float32)
    np.testing.assert_array_equal(ps.interpolate(ps.gather(src)), remap(src))
    codes = rng.integers(0, 4096, (H, W, 3)).astype(np.uint16)
    f = (np.arange(4096) ** 1.7 / 4096).astype(np.float32)      # any per-pixel function with f(0) = 0
    np.testing.assert_array_equal(ps.interpolate(f[ps.gather(codes)]), remap(f[codes]))


# ---- encoder
def _projectors(dev):
    return [
        ProjectorModel(dev, bits=8, response=ResponseCurve((2.2,) * 3), max_radiance=8.0),     # fig4
        ProjectorModel(dev, bits=8, response=ResponseCurve((2.2, 1.0, 0.4)), max_radiance=1.5),
        ProjectorModel(dev, bits=8, response=ResponseCurve((0.3,) * 3), max_radiance=0.7),
        ProjectorModel(dev, bits=10, response=ResponseCurve((2.4,) * 3), max_radiance=3.0),
        ProjectorModel(dev, bits=16, response=ResponseCurve((2.2,) * 3), max_radiance=1.0),    # float path
    ]


@pytest.mark.parametrize("lattice", ["hex", "rect"])
@pytest.mark.parametrize("shift", [0.0, -23.0])
def test_06_encoder_equals_the_float_reference(lattice, shift):
    arr, dev = _rig(lattice, seed=8, shift=shift)
    rng = np.random.default_rng(9)
    for prj in _projectors(dev):
        enc = LightFieldEncoder(arr, prj, U, V)
        assert (enc._quantiser is None) == (prj.bits == 16)
        for lf in (_lf(arr, rng, prj.max_radiance), _lf(arr, rng, 1.5 * prj.max_radiance, lo=-0.3),
                   _lf(arr, rng, 1e-3 * prj.max_radiance)):
            out = enc(lf)
            ref = _ref_encode(prj, enc.codec, lf)
            assert out.dtype == prj.dtype and out.shape == (dev.height, dev.width, 3)
            np.testing.assert_array_equal(out, ref)
            np.testing.assert_array_equal(enc.codec.lightfield_to_image(lf), _ref_lightfield_to_image(enc.codec, lf))


def _values_near_steps(q: _Quantiser, ch: int) -> np.ndarray:
    steps = q.step[ch][np.isfinite(q.step[ch])]
    near = [steps, np.nextafter(steps, np.float32(-np.inf)), np.nextafter(steps, np.float32(np.inf))]
    return np.concatenate(near).astype(np.float32)


@pytest.mark.parametrize("bits, gamma, max_radiance", [(8, (2.2, 2.2, 2.2), 8.0), (8, (2.2, 1.0, 0.4), 1.5),
                                                       (8, (3.0, 0.3, 1.0), 1.0), (10, (2.4, 2.4, 2.4), 3.0),
                                                       (12, (1.0, 1.0, 1.0), 2.0)])
def test_07_quantiser_is_exact_at_every_step(bits, gamma, max_radiance):
    """Bin edges, the values at each step and their float32 neighbours, specials: all equal the float path."""
    _, dev = _rig()
    prj = ProjectorModel(dev, bits=bits, response=ResponseCurve(gamma), max_radiance=max_radiance)
    q = _Quantiser.build(prj)
    assert q is not None
    rng = np.random.default_rng(10)
    special = np.float32([0.0, -0.0, -1.0, -np.inf, np.inf, 1e-38, 1e-45, max_radiance, 2 * max_radiance,
                          np.nextafter(np.float32(max_radiance), np.float32(0)), 3.4e38])
    for ch in range(3):
        x = np.concatenate([_values_near_steps(q, min(ch, len(q.low) - 1)), special,
                            (rng.random(20000) * 1.2 * max_radiance).astype(np.float32),
                            (rng.random(20000) ** 8 * max_radiance).astype(np.float32)])
        img = np.zeros((len(x), 1, 3), np.float32)
        img[:, 0, ch] = x
        got = q(img)[:, 0, ch].astype(np.int64)
        np.testing.assert_array_equal(got, _ref_quantise(prj, img)[:, 0, ch])


@settings(max_examples=40, deadline=None)
@given(gamma=st.floats(0.3, 3.0), max_radiance=st.floats(0.01, 100.0),
       x=st.lists(st.floats(-1.0, 200.0, width=32), min_size=1, max_size=50))
def test_08_quantiser_matches_random_values(gamma, max_radiance, x):
    _, dev = _rig()
    prj = ProjectorModel(dev, bits=8, response=ResponseCurve((gamma,) * 3), max_radiance=max_radiance)
    q = _Quantiser.build(prj)
    assert q is not None
    img = np.repeat(np.asarray(x, np.float32)[:, None, None], 3, axis=2)
    np.testing.assert_array_equal(q(img).astype(np.int64), _ref_quantise(prj, img))


def test_09_sixteen_bit_projector_uses_the_float_path():
    _, dev = _rig()
    assert _Quantiser.build(ProjectorModel(dev, bits=16, response=ResponseCurve((2.2,) * 3))) is None
    assert _Quantiser.build(ProjectorModel(dev, bits=12)) is not None            # linear 12-bit: finer bins


def test_10_row_blocks_on_threads_change_nothing(monkeypatch):
    """The per-pixel table work runs in row blocks on threads at the paper's resolution; forced onto small images
    (every block a few rows, more blocks than rows for the smallest), the codecs still equal the float reference,
    and a projector with cross-talk and a black level encodes as it does in one block."""
    from lftransfer.lightfield import devices

    arr, dev = _rig("hex", seed=11)
    rng = np.random.default_rng(12)
    prj = ProjectorModel(dev, bits=8, response=ResponseCurve((2.2, 2.0, 1.8)), max_radiance=2.0,
                         cross_talk=[[1.0, 0.05, 0.0], [0.04, 1.0, 0.03], [0.0, 0.06, 1.0]],
                         black_level=(0.01, 0.005, 0.008))
    lf = _lf(arr, rng, 2.0)
    one_block = LightFieldEncoder(arr, prj, U, V, above_black=True)(lf)
    monkeypatch.setattr(devices, "_MIN_BLOCK_VALUES", 1)
    for threads in (2, 3, 200):
        monkeypatch.setattr(devices, "CODEC_THREADS", threads)
        monkeypatch.setattr(devices, "_pool", None)
        np.testing.assert_array_equal(LightFieldEncoder(arr, prj, U, V, above_black=True)(lf), one_block)
        test_03_decoder_equals_the_float_reference("hex", 17.5)
        test_06_encoder_equals_the_float_reference("rect", 0.0)
