"""The composite and the sample means: the fast forms equal the plain formulas."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lftransfer.composite import composite
from lftransfer.render.renderer import sample_mean


def _plain(syn, alpha, real):
    return syn + (1.0 - np.clip(alpha, 0.0, 1.0))[..., None] * real


@given(st.integers(0, 2 ** 32 - 1), st.floats(0.0, 1.0))
@settings(max_examples=40, deadline=None)
def test_01_composite_is_the_over_operator_bit_for_bit(seed, cover):
    """Over random coverage (none, a blob, everything): the box-restricted composite equals
    synthetic + (1 - alpha) real over the whole image exactly, where the render is black outside its coverage."""
    rng = np.random.default_rng(seed)
    h, w = 24, 32
    real = rng.random((h, w, 3), dtype=np.float32)
    alpha = np.where(rng.random((h, w)) < cover, rng.random((h, w), dtype=np.float32), 0.0).astype(np.float32)
    syn = (rng.random((h, w, 3), dtype=np.float32) * alpha[..., None]).astype(np.float32)
    out = composite(syn, alpha, real)
    assert out.dtype == np.float32 and out is not real
    np.testing.assert_array_equal(out, _plain(syn, alpha, real).astype(np.float32))
    np.testing.assert_array_equal(real, np.asarray(real))          # the real view is not changed in place


def test_02_composite_refuses_mismatched_shapes():
    with pytest.raises(ValueError, match="shapes differ"):
        composite(np.zeros((4, 4, 3), np.float32), np.zeros((4, 5), np.float32), np.zeros((4, 4, 3), np.float32))


@given(st.integers(1, 8), st.integers(1, 50), st.sampled_from([(), (3,), (2, 3)]), st.integers(0, 2 ** 32 - 1))
@settings(max_examples=60, deadline=None)
def test_03_sample_mean_is_the_mean_of_each_group(spp, groups, tail, seed):
    """(N * spp, ...) -> (N, ...): every group's mean, for any spp and trailing shape (exact for powers of two up
    to the sum's rounding; within float32 rounding otherwise)."""
    values = np.random.default_rng(seed).random((groups * spp, *tail)).astype(np.float32)
    got = sample_mean(values, spp)
    want = values.reshape(groups, spp, *tail).astype(np.float64).mean(axis=1)
    assert got.shape == (groups, *tail) and got.dtype == np.float32
    np.testing.assert_allclose(got, want, rtol=2e-6, atol=1e-7)
