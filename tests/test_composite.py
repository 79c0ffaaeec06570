"""The composite and the sample means: the fast forms equal the plain formulas."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lftransfer.composite import composite
from lftransfer.render.base import sample_mean


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


def _two_planes():
    """An analytic scene seen by a 64 x 48 view camera: a real plane (grey-blue) over the whole frame and a
    synthetic plane (red) over the right two thirds, tilted against each other so that they cross: left of the
    crossing the real plane is nearer, right of it the synthetic one. Depths are exact ray distances."""
    from lftransfer.optics.geometry import backproject, pixel_rays
    from lftransfer.scenes.models import ViewConfig

    view = ViewConfig(resolution=(64, 48), origin=(0.0, 0.0, -0.5), target=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0),
                      fov_deg=40.0)
    h, w = 48, 64
    ys, xs = np.mgrid[0:h, 0:w]
    px = np.stack([xs.ravel(), ys.ravel()], -1).astype(float)
    centre = pixel_rays(view, px)[0]

    def distance(point, normal):
        return np.linalg.norm(backproject(view, px, point, normal) - centre, axis=1).reshape(h, w)

    real_depth = distance((0, 0, 0.0), (0.25, 0.0, 1.0))
    syn_depth = distance((0, 0, 0.0), (-0.25, 0.0, 1.0))
    alpha = (xs >= w // 3).astype(np.float32)
    real = np.broadcast_to(np.float32([0.2, 0.3, 0.6]), (h, w, 3)).astype(np.float32)
    syn = (np.float32([0.9, 0.1, 0.1]) * alpha[..., None]).astype(np.float32)
    syn_depth = np.where(alpha > 0, syn_depth, np.inf)
    return syn, alpha, syn_depth, real, real_depth


def test_03_depth_composite_of_two_crossing_planes():
    """Away from the planes' crossing (depths more than 5 sigma apart) the depth composite is exact: the nearer
    surface's colour; across it, every pixel is a blend of the two colours (a soft edge, no halo); unknown real
    depth falls back to the over operator. Negative control: the over operator is wrong wherever the real plane is
    nearer."""
    from lftransfer.composite import composite_depth, front_weight

    syn, alpha, syn_depth, real, real_depth = _two_planes()
    sigma = 0.002
    out = composite_depth(syn, alpha, syn_depth, real, real_depth, sigma)
    gap = real_depth - syn_depth
    covered = alpha > 0
    front, behind = covered & (gap > 5 * np.hypot(sigma, 0.001)), covered & (gap < -5 * np.hypot(sigma, 0.001))
    assert front.sum() > 200 and behind.sum() > 200          # both orders occur
    np.testing.assert_allclose(out[front], syn[front], atol=1e-5)
    np.testing.assert_allclose(out[behind], real[behind], atol=1e-5)
    np.testing.assert_array_equal(out[~covered], real[~covered])
    w = front_weight(syn_depth, real_depth, sigma)
    edge = covered & ~front & ~behind
    assert edge.any() and np.all((w[edge] > 0) & (w[edge] < 1))
    np.testing.assert_allclose(out[edge], w[edge][:, None] * syn[edge] + (1 - w[edge][:, None]) * real[edge],
                               atol=1e-6)
    # unknown real depth: the over operator
    unknown = composite_depth(syn, alpha, syn_depth, real, np.full_like(real_depth, np.nan), sigma)
    np.testing.assert_allclose(unknown, composite(syn, alpha, real), atol=1e-6)
    # negative control: the over operator shows the synthetic plane where the real one hides it
    over = composite(syn, alpha, real)
    assert np.abs(over[behind] - real[behind]).max() > 0.5
