"""Window-model geometry: light crossing the interface through lenslet k goes on straight."""

from __future__ import annotations

import numpy as np

from lftransfer.lightfield import LightField
from lftransfer.optics import LensArray
from lftransfer.render.lights import LightFieldLight
from lftransfer.render.renderer import HalfSpaceRenderer
from lftransfer.scenes.format import ObjectConfig


def _plane(z, rot):
    return ObjectConfig.model_validate({"name": "plane", "shape": "rectangle", "size": [1.0, 1.0],
                                        "translate": [0.0, 0.0, z], "rotate_deg": rot,
                                        "material": {"type": "diffuse", "albedo": [0.5, 0.5, 0.5]}})


def _brightest_point(renderer, lights, z, facing, half=0.06, n=121):
    xs = np.linspace(-half, half, n)
    gx, gy = np.meshgrid(xs, xs)
    pts = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, z)], -1)
    o = pts + 0.01 * np.asarray(facing)
    rad, hit, _ = renderer.render_rays(o, np.broadcast_to(-np.asarray(facing, float), o.shape), lights)
    assert hit.all()
    i = int(np.argmax(rad.sum(1)))
    return pts[i, :2], xs[1] - xs[0]


def test_01_single_ray_continues_straight_on_both_sides(variant):
    array = LensArray(lattice="hex", rows=3, cols=3, pitch=0.0254, focal_length=0.0254)
    U = 16
    lf = LightField.zeros(array, U, U)
    k, j, i = 4, 11, 3
    lf.data[k, j, i] = 1.0
    u, v = lf.u[i], lf.v[j]
    c = array.centres[k]
    h = 0.08
    step = h * 2 * array.half_width / U          # one angular sample, seen at distance h
    # Captured real light (travelling along -d) continues into the synthetic half-space: c - h (u, v).
    synth = HalfSpaceRenderer([_plane(-h, [0, 0, 0])], max_depth=1)
    p, dx = _brightest_point(synth, [LightFieldLight(lf, "synthetic", model="point")], -h, [0, 0, 1])
    np.testing.assert_allclose(p, c - h * np.array([u, v]), atol=step + dx)
    # Projected light (travelling along +d) lands in the real half-space at c + h (u, v).
    real = HalfSpaceRenderer([_plane(h, [180, 0, 0])], max_depth=1)
    p, dx = _brightest_point(real, [LightFieldLight(lf, "real", model="point")], h, [0, 0, -1])
    np.testing.assert_allclose(p, c + h * np.array([u, v]), atol=step + dx)


def test_02_points_on_the_wrong_side_get_no_light(variant):
    array = LensArray(lattice="rect", rows=1, cols=1, pitch=0.02, focal_length=0.02)
    lf = LightField.zeros(array, 8, 8)
    lf.data[...] = 1.0
    real = HalfSpaceRenderer([_plane(0.05, [180, 0, 0])], max_depth=1)
    rad, hit, _ = real.render_rays(np.array([[0.0, 0.0, 0.04]]), np.array([[0.0, 0.0, 1.0]]),
                                   [LightFieldLight(lf, "synthetic", model="area")])
    assert hit[0] and np.all(rad == 0)


def test_03_linear_blend_is_found_once_and_lights_the_neighbours_of_a_lit_lenslet(variant):
    """The linear reconstruction's blend depends on the rig and the seed only: a second light reuses it (a live
    loop builds a light per frame). With one lenslet lit, the lenslets whose apertures read it carry light too:
    exactly those whose blend indices name it with a positive weight (the negative control: the box
    reconstruction visits the lit lenslet alone)."""
    array = LensArray(lattice="hex", rows=4, cols=5, pitch=0.0254, focal_length=0.0254)
    lf = LightField.zeros(array, 8, 8)
    lit = 7
    lf.data[lit] = lf.mask()[..., None]
    first = LightFieldLight(lf, "synthetic", model="area", reconstruction="linear", seed=3)
    second = LightFieldLight(lf, "synthetic", model="area", reconstruction="linear", seed=3)
    assert second._blend_idx is not first._blend_idx                   # its own Dr.Jit arrays ...
    from lftransfer.render.lights.sampling import linear_blend

    blend = linear_blend(array, first.pool, 3)
    assert linear_blend.cache_info().hits >= 1                          # ... from the same blend
    idx = blend.index.reshape(array.K, -1)
    w = blend.weight.reshape(array.K, -1)
    expected = np.flatnonzero(((idx == lit) & (w > 0)).any(axis=1))
    np.testing.assert_array_equal(first.active_lenslets, expected)
    assert lit in expected and len(expected) >= 4                        # the lit one and its neighbours
    box = LightFieldLight(lf, "synthetic", model="area", reconstruction="box", seed=3)
    np.testing.assert_array_equal(box.active_lenslets, [lit])


def test_04_edge_table_gathered_by_drjit_equals_the_numpy_extension(variant):
    """The light's extended table (:func:`extended_table`, one Dr.Jit gather per frame from an index found once per
    steep-ray set) is :func:`extend_beyond_window`'s table bit for bit: without a depth, and with a depth whose
    check drops some steep rays (those read zero). A second light of the same steep rays reuses the index."""
    from lftransfer.lightfield.window import extend_beyond_window, steep_rays
    from lftransfer.backend import mitsuba
    from lftransfer.render.lights import sampling
    from lftransfer.render.lights import EDGE_REACH, extended_table

    array = LensArray(lattice="hex", rows=3, cols=4, pitch=0.0254, focal_length=0.0254)
    rng = np.random.default_rng(4)
    lf = LightField(rng.random((array.K, 12, 12, 3)).astype(np.float32) + 0.1, array)
    depth = rng.uniform(0.03, 0.2, (array.K, 12, 12))
    depth[rng.random(depth.shape) < 0.3] = np.nan
    for d in (None, depth):
        steep = steep_rays(lf, EDGE_REACH, d)
        expected = extend_beyond_window(lf, steep).data
        got = np.array(extended_table(lf.data, steep))
        np.testing.assert_array_equal(got, expected.ravel())
        if d is not None:
            assert steep.kept < 1.0 and (expected == 0).any()          # the check dropped some: zeros read
        index = sampling._edge_index(steep, mitsuba().variant())
        light = LightFieldLight(lf, "synthetic", model="area", window="edge", steep=steep)
        assert sampling._edge_index(steep, mitsuba().variant()) is index
        np.testing.assert_array_equal(np.array(light._table), expected.ravel())
