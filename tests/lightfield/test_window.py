"""A light field read beyond its lenslets' window: the window's edge, checked against the real scene's depth."""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.lightfield import LightField
from lftransfer.lightfield.window import extend_beyond_window, steep_rays
from lftransfer.optics import LensArray

P = 0.02
Z = 0.05                      # m, the real patch's depth
HALF = 0.03                   # m, the patch's half-width (the array spans +-0.09 m)
REACH = 1.5


def _patch(lattice: str, background: str) -> tuple[LightField, np.ndarray]:
    """A diffuse square patch of radiance 1 at depth Z seen through a 9 x 9 array; around it nothing (depth NaN)
    or a far plane of radiance 0.5 at 0.5 m. Returns (light field, (K, V, U) depth of each centre ray)."""
    lf = LightField.zeros(LensArray(lattice, 9, 9, P, P), 16, 16)
    uu, vv = np.meshgrid(lf.u, lf.v)
    c = lf.array.centres
    x, y = c[:, 0, None, None] + Z * uu[None], c[:, 1, None, None] + Z * vv[None]
    on = (np.abs(x) < HALF) & (np.abs(y) < HALF) & lf.mask()[None]
    far = ~on & lf.mask()[None] & (background == "far")
    lf.data[...] = (on + 0.5 * far)[..., None].astype(np.float32)
    depth = np.where(on, Z, np.where(far, 0.5, np.nan))
    return lf, depth


def _steep(lf: LightField, margin: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The extended grid's directions (Ve, Ue) u, v and which of them lie beyond the window within the reach."""
    a, U, V = lf.array.half_width, lf.U, lf.V
    ue = -a + (np.arange(U + 2 * margin) - margin + 0.5) * 2 * a / U
    ve = -a + (np.arange(V + 2 * margin) - margin + 0.5) * 2 * a / V
    uu, vv = np.meshgrid(ue, ve)
    inside = np.zeros(uu.shape, bool)
    inside[margin:margin + V, margin:margin + U] = lf.mask()
    return uu, vv, ~inside & (uu**2 + vv**2 <= (REACH * a) ** 2)


@pytest.mark.parametrize("lattice", ["rect", "hex"])
def test_01_without_depth_every_steep_sample_is_its_nearest_edge_sample(lattice):
    """The table's middle is the light field; each sample beyond the window is the nearest one inside (the
    distance on the sample grid), so a light field constant in direction stays constant out to the reach."""
    lf, _ = _patch(lattice, "none")
    lf.data[...] = np.random.default_rng(1).random(lf.data.shape).astype(np.float32) * lf.mask()[None, ..., None]
    steep = steep_rays(lf, REACH)
    ext = extend_beyond_window(lf, steep)
    m = ext.margin
    assert steep.kept == 1.0
    np.testing.assert_array_equal(ext.data[:, m:m + lf.V, m:m + lf.U][:, lf.mask()], lf.data[:, lf.mask()])
    uu, vv, steep = _steep(lf, m)
    assert np.hypot(uu, vv)[steep].max() > 1.4 * lf.array.half_width          # the margin covers the reach
    iv, iu = np.nonzero(lf.mask())
    for r, c in zip(*np.nonzero(steep)):                                        # a few hundred directions
        d2 = (iv + m - r) ** 2 + (iu + m - c) ** 2
        nearest = d2 == d2.min()
        assert any(np.array_equal(ext.data[:, r, c], lf.data[:, v, u]) for v, u in zip(iv[nearest], iu[nearest]))
    flat = LightField.zeros(lf.array, 16, 16)
    flat.data[...] = 2.0 * lf.mask()[None, ..., None]
    out = extend_beyond_window(flat, steep_rays(flat, REACH)).data
    np.testing.assert_array_equal(out[:, steep], 2.0)


@pytest.mark.parametrize("background", ["none", "far"])
@pytest.mark.parametrize("lattice", ["rect", "hex"])
def test_02_the_depth_keeps_the_steep_rays_that_still_meet_the_surface(lattice, background):
    """A small real patch seen at the window's edge: a steep ray followed to the patch's depth keeps its edge
    value where it still lands on the patch and is zeroed where it passes beside it (onto nothing, or onto a far
    plane at ten times the depth). Decided within half a sample's footprint of the patch's border. Without the
    depth (the control) the rays beside the patch keep the patch's light."""
    lf, depth = _patch(lattice, background)
    checked = steep_rays(lf, REACH, depth)
    ext = extend_beyond_window(lf, checked)
    bare = extend_beyond_window(lf, steep_rays(lf, REACH))
    m = ext.margin
    uu, vv, steep = _steep(lf, m)
    c = lf.array.centres
    lands = c[:, None, :] + Z * np.stack([uu[steep], vv[steep]], -1)[None]     # (K, n) where a steep ray meets z = Z
    from_patch = bare.data[:, steep, 0] == 1.0                                 # its edge sample saw the patch
    central = (np.abs(c) < 0.045).all(axis=1)[:, None]                          # its landing point lies on the array
    footprint = 0.5 * Z * 2 * lf.array.half_width / lf.U + 1e-9
    border = np.abs(lands).max(axis=-1) - HALF                                 # > 0: beside the patch
    on = from_patch & central & (border < -footprint)
    beside = from_patch & central & (border > footprint)
    assert on.sum() > 200 and beside.sum() > 200
    value = ext.data[:, steep, 0]
    assert np.all(value[on] == 1.0)
    assert np.all(value[beside] == 0.0)
    assert np.all(bare.data[:, steep, 0][beside] == 1.0)                       # the control reads the patch there
    assert 0.0 < checked.kept < 1.0
    middle = np.s_[:, m:m + lf.V, m:m + lf.U]
    np.testing.assert_array_equal(ext.data[middle][:, lf.mask()], lf.data[:, lf.mask()])  # the window untouched


def test_03_bad_reach_depth_or_shape_is_refused():
    lf, depth = _patch("rect", "none")
    with pytest.raises(ValueError, match="reach"):
        steep_rays(lf, 1.0)
    with pytest.raises(ValueError, match="depth has shape"):
        steep_rays(lf, REACH, depth[:, :4])
    other = LightField.zeros(lf.array, 8, 8)
    with pytest.raises(ValueError, match="shape"):
        extend_beyond_window(other, steep_rays(lf, REACH))
