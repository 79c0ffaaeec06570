"""Projector colour cross-talk and black level: the forward model, its inverse in the encoder, validation."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lftransfer.lightfield import LightField, LightFieldEncoder, ProjectorModel, ResponseCurve
from lftransfer.optics import LensArray, LensletDevice

P = 0.0254
U = V = 12


def _rig(lattice="hex", width=160, height=120):
    arr = LensArray(lattice, 3, 4, P, P, rotation=0.1, offset=(0.004, -0.003))
    rng = np.random.default_rng(0)
    dist = np.column_stack([rng.uniform(-0.1, 0.1, arr.K), rng.uniform(-0.03, 0.03, arr.K)])
    return arr, LensletDevice.fronto_parallel(arr, width, height, distortion=dist)


ARR, DEV = _rig()
C0 = np.array([[1.03, 0.04, 0.01], [0.02, 0.96, 0.05], [0.00, 0.03, 1.01]])


def _in_gamut_lf(prj: ProjectorModel, rng: np.random.Generator) -> LightField:
    """Radiance the projector can emit: max * (b + C @ drive) with drives in [0, 1] (a convex set)."""
    lf = LightField.zeros(ARR, U, V)
    drive = rng.random(lf.data.shape)
    lf.data[:] = prj.max_radiance * (np.asarray(prj.black_level) + drive @ prj.cross_talk_matrix.T)
    return lf


def test_01_plain_projector_keeps_the_plain_path():
    rng = np.random.default_rng(1)
    prj = ProjectorModel(DEV, response=ResponseCurve((2.2,) * 3), max_radiance=3.0)
    same = replace(prj, cross_talk=np.eye(3), black_level=(0, 0, 0))
    assert not prj.mixes_colours and not same.mixes_colours
    assert replace(prj, black_level=(0, 0.01, 0)).mixes_colours and replace(prj, cross_talk=C0).mixes_colours
    lf = LightField.zeros(ARR, U, V)
    lf.data[:] = rng.random(lf.data.shape) * 3.2
    a, b = LightFieldEncoder(ARR, prj, U, V), LightFieldEncoder(ARR, same, U, V)
    assert a._affine is None and b._affine is None
    np.testing.assert_array_equal(a(lf), b(lf))
    codes = rng.integers(0, 256, (DEV.height, DEV.width, 3)).astype(np.uint8)
    np.testing.assert_array_equal(a.emitted(codes), b.emitted(codes))
    np.testing.assert_array_equal(prj.cross_talk_matrix, np.eye(3))


def test_02_forward_model():
    """emitted = max_radiance * (black_level + C @ decode(code / levels)) per pixel."""
    rng = np.random.default_rng(2)
    prj = ProjectorModel(DEV, bits=8, response=ResponseCurve((2.0, 2.2, 2.5)), max_radiance=7.5, cross_talk=C0,
                         black_level=(0.01, 0.004, 0.0))
    codes = rng.integers(0, 256, (DEV.height, DEV.width, 3)).astype(np.uint8)
    codes[0, 0] = 0
    out = LightFieldEncoder(ARR, prj, U, V).emitted(codes)
    assert out.dtype == np.float32 and out.shape == codes.shape
    drive = (codes / 255.0) ** np.array([2.0, 2.2, 2.5])
    expected = 7.5 * (np.array([0.01, 0.004, 0.0]) + drive @ C0.T)
    np.testing.assert_allclose(out, expected, rtol=2e-6, atol=1e-6)
    np.testing.assert_allclose(out[0, 0], 7.5 * np.array([0.01, 0.004, 0.0]), atol=1e-6)


@settings(max_examples=25, deadline=None)
@given(off=st.lists(st.floats(0.0, 0.08), min_size=6, max_size=6),
       diag=st.lists(st.floats(0.9, 1.1), min_size=3, max_size=3),
       black=st.lists(st.floats(0.0, 0.05), min_size=3, max_size=3),
       gamma=st.lists(st.floats(1.0, 3.0), min_size=3, max_size=3),
       max_radiance=st.floats(0.5, 20.0), bits=st.sampled_from([8, 10]), seed=st.integers(0, 2**16))
def test_03_emitted_of_encoded_reproduces_the_radiance(off, diag, black, gamma, max_radiance, bits, seed):
    c = np.diag(diag)
    c[~np.eye(3, dtype=bool)] = off
    prj = ProjectorModel(DEV, bits=bits, response=ResponseCurve(tuple(gamma)), max_radiance=max_radiance,
                         cross_talk=c, black_level=tuple(black))
    enc = LightFieldEncoder(ARR, prj, U, V)
    assert enc._quantiser is not None
    lf = _in_gamut_lf(prj, np.random.default_rng(seed))
    codes = enc(lf)
    assert codes.dtype == prj.dtype and codes.shape == (DEV.height, DEV.width, 3)
    target = enc.codec.lightfield_to_image(lf)
    covered = enc.codec.inv_norm3[..., 0] > 0
    # half a code step of each channel's drive (slope of code^gamma <= gamma), mixed by C, plus float rounding
    tol = max_radiance * (np.abs(c) @ (np.asarray(gamma) * 0.5 / prj.levels)) + 1e-5 * max_radiance
    err = np.abs(enc.emitted(codes) - target)[covered]
    assert np.all(err <= tol), (err.max(axis=0), tol)
    # off the lenslets radiance 0 is asked for: the drives the formula gives for 0 (clipped at 0)
    zero = enc.quantise(np.zeros((DEV.height, DEV.width, 3), np.float32))
    np.testing.assert_array_equal(codes[~covered], zero[~covered])
    # the per-pixel quantiser alone: emitted -> quantise -> emitted is stable to within the same steps
    again = enc.emitted(enc.quantise(enc.emitted(codes)))
    assert np.all(np.abs(again - enc.emitted(codes)) <= tol)


def test_04_out_of_gamut_radiance_is_clipped_per_drive():
    prj = ProjectorModel(DEV, response=ResponseCurve((2.2,) * 3), max_radiance=2.0, cross_talk=C0,
                         black_level=(0.01, 0.01, 0.01))
    enc = LightFieldEncoder(ARR, prj, U, V)
    img = np.zeros((DEV.height, DEV.width, 3), np.float32)
    img[0, 0] = [100.0, 100.0, 100.0]          # far too bright: every drive at full
    img[0, 1] = [-1.0, -1.0, -1.0]             # below black: nothing driven
    img[0, 2] = [2.0, 0.0, 0.0]                # pure red cannot be made: red driven, the others clipped at 0
    codes = enc.quantise(img)
    assert codes[0, 0].tolist() == [255, 255, 255] and codes[0, 1].tolist() == [0, 0, 0]
    assert codes[0, 2, 0] > 0 and codes[0, 2, 1] == 0 and codes[0, 2, 2] == 0


def test_05_sixteen_bit_projector_with_cross_talk_uses_the_float_path():
    rng = np.random.default_rng(5)
    prj = ProjectorModel(DEV, bits=16, response=ResponseCurve((2.2,) * 3), max_radiance=4.0, cross_talk=C0,
                         black_level=(0.002, 0.0, 0.001))
    enc = LightFieldEncoder(ARR, prj, U, V)
    assert enc._quantiser is None
    lf = _in_gamut_lf(prj, rng)
    codes = enc(lf)
    assert codes.dtype == np.uint16
    covered = enc.codec.inv_norm3[..., 0] > 0
    err = np.abs(enc.emitted(codes) - enc.codec.lightfield_to_image(lf))[covered]
    assert err.max() < 4.0 * 1.2 * 2.2 * 0.5 / 65535 + 1e-4


@pytest.mark.parametrize("kwargs, match", [
    ({"cross_talk": np.eye(2)}, r"shape \(3, 3\)"),
    ({"cross_talk": [[1, 0, 0], [0, np.nan, 0], [0, 0, 1]]}, "finite"),
    ({"cross_talk": [[1, 1, 0], [1, 1, 0], [0, 0, 1]]}, "invertible"),
    ({"cross_talk": "identity"}, "cross_talk"),
    ({"black_level": (0.0, 0.2, 0.0)}, r"\[0, 0.2\)"),
    ({"black_level": (-0.01, 0.0, 0.0)}, r"\[0, 0.2\)"),
    ({"black_level": (0.0, 0.0)}, "three numbers"),
    ({"black_level": (0.0, float("nan"), 0.0)}, "three numbers"),
])
def test_06_invalid_cross_talk_or_black_level(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ProjectorModel(DEV, **kwargs)


def test_07_cross_talk_is_copied_and_read_only():
    c = C0.copy()
    prj = ProjectorModel(DEV, cross_talk=c)
    c[0, 0] = 5.0
    assert prj.cross_talk[0, 0] == pytest.approx(1.03)
    with pytest.raises(ValueError):
        prj.cross_talk[0, 0] = 2.0
    affine = prj.drive_affine()
    assert affine.shape == (3, 4)
    np.testing.assert_allclose(affine[:, :3] @ C0, np.eye(3) / prj.max_radiance, atol=1e-12)


def test_08_above_black_adds_the_light_field_to_the_black_level():
    """The transfer measures each projection against a frame with the projector black, so it encodes light to
    add to the black level: emitted(encode(L)) - emitted(black) = L (to within the codes' steps), dim entries
    included. Encoding L as the whole radiance (the negative control) takes the black level off every entry
    and drops the entries below it."""
    rng = np.random.default_rng(8)
    black = (0.01, 0.006, 0.002)
    prj = ProjectorModel(DEV, bits=8, response=ResponseCurve((2.2,) * 3), max_radiance=8.0, cross_talk=C0,
                         black_level=black)
    lf = LightField.zeros(ARR, U, V)
    # dim light the projector can add, drives of 0 to 5 % of the maximum
    lf.data[:] = prj.max_radiance * (0.05 * rng.random(lf.data.shape)) @ prj.cross_talk_matrix.T
    added = LightFieldEncoder(ARR, prj, U, V, above_black=True)
    whole = LightFieldEncoder(ARR, prj, U, V)
    covered = added.codec.inv_norm3[..., 0] > 0
    target = added.codec.lightfield_to_image(lf)[covered]
    zero = np.zeros((DEV.height, DEV.width, 3), np.uint8)
    for enc in (added, whole):
        assert np.all(enc(LightField.zeros(ARR, U, V)) == 0)                # black is code 0 either way
    got = (added.emitted(added(lf)) - added.emitted(zero))[covered]
    # half a code step at 5 % of the maximum: gamma * code^(gamma - 1) * 0.5 / 255, mixed by C
    step = prj.max_radiance * 2.2 * 0.05 ** (1.2 / 2.2) * 0.5 / 255 * np.abs(C0).sum(1).max()
    assert np.abs(got - target).max() <= step
    assert abs(got.sum() / target.sum() - 1) < 0.001                        # measured 0.00004
    lost = (whole.emitted(whole(lf)) - whole.emitted(zero))[covered]
    assert lost.sum() / target.sum() < 0.85                 # the control loses the black level: measured 0.78
