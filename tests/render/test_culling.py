"""Culling primary rays by tile: conservative (no ray that meets an object is left out) and the renders unchanged."""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.render.camera import sensor_dict
from lftransfer.render.culling import TILE, RayTiles
from lftransfer.render.fast import CachedRenderer
from lftransfer.render.fast import rays as rays_module
from lftransfer.render.lights import PointLight
from tests.render.test_fast import ARRAY, _objects


def _meets(origins, directions, centre, radius):
    """(N,) bool: the ray meets the sphere (analytic, ahead of its origin)."""
    oc = origins - centre
    b = np.einsum("nk,nk->n", oc, directions)
    c = np.einsum("nk,nk->n", oc, oc) - radius**2
    disc = b * b - c
    far = -b + np.sqrt(np.maximum(disc, 0.0))
    return (disc >= 0) & (far >= 0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_01_no_ray_that_meets_a_sphere_is_left_out(seed):
    rng = np.random.default_rng(seed)
    # pinhole-like tiles (a shared origin, neighbouring directions) and lenslet-like ones (origins over an aperture)
    n = 400 * TILE
    centre_dir = rng.normal(size=(n // TILE, 3))
    centre_dir[:, 2] = -np.abs(centre_dir[:, 2]) - 1.0
    d = np.repeat(centre_dir, TILE, axis=0) + 0.05 * rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.repeat(rng.uniform(-0.05, 0.05, size=(n // TILE, 3)), TILE, axis=0)
    o[n // 2:] += rng.uniform(-0.0127, 0.0127, size=(n - n // 2, 3)) * [1, 1, 0]
    tiles = RayTiles.of(o, d)
    pinholes = RayTiles(count=n, apex=tiles.apex, axis=tiles.axis, half_angle=tiles.half_angle,
                        spread=np.zeros_like(tiles.spread))      # control: origins taken as one point
    control_missed = 0
    for _ in range(20):
        centre = rng.uniform([-0.1, -0.1, -0.3], [0.1, 0.1, -0.05])
        radius = rng.uniform(0.005, 0.05)
        meet = _meets(o, d, centre, radius)
        chosen = tiles.meeting(centre[None], np.array([radius]))
        kept = np.zeros(n, bool)
        kept[tiles.rays(chosen)] = True
        assert not np.any(meet & ~kept)              # conservative
        lost = np.ones(n, bool)
        lost[pinholes.rays(pinholes.meeting(centre[None], np.array([radius])))] = False
        control_missed += int(np.sum(meet & lost))
        assert chosen.mean() < 0.9                   # and it does cull
    assert control_missed > 0                        # the test sees a cone that is too narrow
    assert tiles.half_angle.max() < 0.3


def test_02_rays_of_the_last_short_tile():
    o = np.zeros((TILE + 5, 3))
    d = np.tile([0.0, 0.0, -1.0], (TILE + 5, 1))
    tiles = RayTiles.of(o, d)
    assert len(tiles.apex) == 2
    np.testing.assert_array_equal(tiles.rays(np.array([False, True])), np.arange(TILE, TILE + 5))


def test_03_culled_renders_equal_whole_ones(variant, monkeypatch):
    """A second render of the same rays (a live loop's next frame) casts only the tiles that can meet an object,
    and equals a render that casts every ray."""
    from lftransfer.backend import mitsuba

    mi = mitsuba()
    light = [PointLight(np.array([0.2, 0.15, 0.0]), np.array([1.0, 0.8, 0.6]))]
    sensor = mi.load_dict(sensor_dict([0.3, 0.1, 0.0], [0.0, 0.0, -0.07], [0, 1, 0], 30.0, 192, 144))
    renders, shares = {}, []
    meeting = RayTiles.meeting

    def recorded(self, centres, radii):
        chosen = meeting(self, centres, radii)
        shares.append(chosen.mean())
        return chosen

    monkeypatch.setattr(RayTiles, "meeting", recorded)
    for cull in (1.0, 0.0):              # always cull / never
        monkeypatch.setattr(rays_module, "CULL_BELOW", cull)
        r = CachedRenderer(_objects())
        ball = CachedRenderer(_objects()[1:])            # small: most light field tiles miss it
        for _ in range(2):           # the tiles are built at a ray set's second render
            renders[cull] = (r.render_view(sensor, 192, 144, light, spp=4),
                             ball.render_lightfield(ARRAY, light, 24, 24, model="area", spp=4))
    (view_c, lf_c), (view, lf) = renders[1.0], renders[0.0]
    assert max(shares[:2]) < 1.0                     # both renders were culled (the view and the light field)
    assert view.alpha.mean() > 0.02 and lf.data.max() > 0
    np.testing.assert_array_equal(view_c.alpha, view.alpha)
    np.testing.assert_allclose(view_c.rgb, view.rgb, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(view_c.depth, view.depth, rtol=1e-6)
    np.testing.assert_allclose(lf_c.data, lf.data, rtol=1e-6, atol=1e-9)


def test_04_a_still_scene_culls_once_and_a_moved_object_culls_again(variant, monkeypatch):
    """The tiles are tested against the objects' spheres once while nothing moves (the same rays cast, the same
    image); a moved object is culled again, and its render equals one of a renderer that never culled."""
    from lftransfer.backend import mitsuba

    mi = mitsuba()
    light = [PointLight(np.array([0.2, 0.15, 0.0]), np.array([1.0, 0.8, 0.6]))]
    sensor = mi.load_dict(sensor_dict([0.3, 0.1, 0.0], [0.0, 0.0, -0.07], [0, 1, 0], 30.0, 192, 144))
    calls = []
    meeting = RayTiles.meeting
    monkeypatch.setattr(RayTiles, "meeting", lambda self, c, r: calls.append(1) or meeting(self, c, r))
    monkeypatch.setattr(rays_module, "CULL_BELOW", 1.0)
    r = CachedRenderer(_objects())
    views = [r.render_view(sensor, 192, 144, light, spp=4) for _ in range(4)]
    assert len(calls) == 1                                   # tiles built at the 2nd render, tested once
    for v in views[2:]:
        np.testing.assert_array_equal(v.rgb, views[1].rgb)
    moved = [o.model_copy(update={"translate": [o.translate[0] + 0.01, *o.translate[1:]]}) for o in _objects()]
    assert r.update(moved)
    after = r.render_view(sensor, 192, 144, light, spp=4)
    assert len(calls) == 2                                   # culled again for the moved spheres
    monkeypatch.setattr(rays_module, "CULL_BELOW", 0.0)       # the control: every ray cast
    whole = CachedRenderer(moved)
    for _ in range(2):
        reference = whole.render_view(sensor, 192, 144, light, spp=4)
    np.testing.assert_array_equal(after.alpha, reference.alpha)
    np.testing.assert_allclose(after.rgb, reference.rgb, rtol=1e-6, atol=1e-9)
    assert not np.array_equal(after.alpha, views[-1].alpha)   # negative control: the object did move
