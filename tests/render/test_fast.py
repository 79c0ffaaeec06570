"""The fast path (irradiance cached at tessellation vertices) against the exact path, at small resolution."""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.lightfield import LightField
from lftransfer.optics import LensArray
from lftransfer.render.camera import sensor_dict
from lftransfer.render.fast import CachedRenderer, supports, tessellate
from lftransfer.render.lights import LightFieldLight, PointLight
from lftransfer.render.renderer import HalfSpaceRenderer
from lftransfer.scenes.format import ObjectConfig
from lftransfer.sim.verify import psnr

ARRAY = LensArray(lattice="hex", rows=3, cols=4, pitch=0.0254, focal_length=0.0254)


def _objects(material=None):
    mat = material or {"type": "diffuse", "albedo": [0.3, 0.8, 0.4]}
    return [ObjectConfig.model_validate({"name": "cube", "shape": "box", "size": [0.05] * 3,
                                         "translate": [0.0, 0.0, -0.08], "rotate_deg": [0, 30, 0], "material": mat}),
            ObjectConfig.model_validate({"name": "ball", "shape": "sphere", "radius": 0.015,
                                         "translate": [0.05, 0.02, -0.06], "material": mat})]


def _incident():
    """A smooth, direction-dependent captured light field (radiance travelling into z < 0)."""
    lf = LightField.zeros(ARRAY, 12, 12)
    uu, vv = np.meshgrid(lf.u, lf.v)
    k = np.arange(ARRAY.K)[:, None, None]
    lf.data[..., 0] = 1.0 + 0.5 * uu + 0.1 * k / ARRAY.K
    lf.data[..., 1] = 0.8 - 0.4 * vv
    lf.data[..., 2] = 0.5 + 0.3 * uu * vv
    lf.data *= lf.mask()[None, :, :, None]
    return lf


def _views(lights_fast, lights_exact, spp=4):
    from lftransfer.backend import mitsuba

    mi = mitsuba()
    sensor = mi.load_dict(sensor_dict([0.3, 0.1, 0.0], [0.0, 0.0, -0.07], [0, 1, 0], 30.0, 96, 72))
    fast = CachedRenderer(_objects()).render_view(sensor, 96, 72, lights_fast, spp=spp)
    exact = HalfSpaceRenderer(_objects(), max_depth=1).render_view(sensor, 96, 72, lights_exact, spp=spp)
    return fast, exact


def test_01_tessellation(variant):
    cube, ball = _objects()
    v, n = tessellate(cube, 0.006)
    edges = np.linalg.norm(v.reshape(-1, 3, 3) - np.roll(v.reshape(-1, 3, 3), 1, axis=1), axis=-1)
    assert edges.max() <= 0.006 + 1e-6
    tri = v.reshape(-1, 3, 3)
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum()
    assert area == pytest.approx(6 * 0.05**2, rel=1e-5)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-5)
    v, n = tessellate(ball, 0.006)
    r = np.linalg.norm(v - np.array([0.05, 0.02, -0.06]), axis=1)
    np.testing.assert_allclose(r, 0.015, rtol=1e-5)


def test_02_point_light_matches_exact(variant):
    light = [PointLight(np.array([0.2, 0.15, 0.0]), np.array([1.0, 0.8, 0.6]))]
    fast, exact = _views(light, light)
    np.testing.assert_array_equal(fast.alpha, exact.alpha)
    assert psnr(fast.rgb, exact.rgb) > 40
    # Light fields: each object alone matches closely; together, the sphere's shadow on the cube has edges
    # blurred over one cache triangle (6 mm), which a 12 x 12 point-sampled light field sees.
    for objects, tol in ((_objects()[:1], 0.002), (_objects()[1:], 0.01), (_objects(), 0.06)):
        lf_fast = CachedRenderer(objects).render_lightfield(ARRAY, light, 12, 12, model="point", spp=1)
        lf_exact = HalfSpaceRenderer(objects, max_depth=1).render_lightfield(ARRAY, light, 12, 12, model="point",
                                                                           spp=1)
        assert np.abs(lf_fast.data - lf_exact.data).sum() < tol * lf_exact.data.sum()


@pytest.mark.parametrize("model", ["point", "prefiltered", "area"])
def test_03_light_field_lighting_matches_exact(variant, model):
    incident = _incident()
    m = 64 if model == "area" else 1
    fast_light = [LightFieldLight(incident, "synthetic", model=model, aperture_samples=m, jitter=False)]
    exact_light = [LightFieldLight(incident, "synthetic", model=model, aperture_samples=m, jitter=False)]
    fast, exact = _views(fast_light, exact_light)
    assert exact.rgb.max() > 0
    assert psnr(fast.rgb, exact.rgb) > 35, model


def test_04_only_diffuse(variant):
    glossy = _objects({"type": "glossy", "albedo": [0.5] * 3, "roughness": 0.2})
    assert not supports(glossy) and supports(_objects())
    with pytest.raises(ValueError, match="diffuse"):
        CachedRenderer(glossy)
    from lftransfer.scenes import builtin_scene, load_scene, with_overrides
    from lftransfer.transfer.synthetic_side import synthetic_renderer

    scene = load_scene(builtin_scene("fig4"))
    assert isinstance(synthetic_renderer(scene), CachedRenderer)
    shiny = with_overrides(scene, synthetic=[{**scene.synthetic[0].model_dump(mode="json"),
                                              "material": {"type": "glossy", "roughness": 0.3}}])
    assert type(synthetic_renderer(shiny)) is HalfSpaceRenderer


def test_05_moved_objects_equal_a_fresh_cache(variant):
    """Moving objects updates the cache in place: the result equals a cache built at the new poses, the exact
    renderer's update agrees, and nothing is rebuilt when nothing moved."""
    from lftransfer.backend import mitsuba

    mi = mitsuba()
    sensor = mi.load_dict(sensor_dict([0.3, 0.1, 0.0], [0.0, 0.0, -0.07], [0, 1, 0], 30.0, 48, 36))
    light = PointLight(np.array([0.3, 0.1, -0.02]), np.array([1.0, 1.0, 1.0]))
    moved = [o.model_copy(update={"translate": [o.translate[0] + 0.01, o.translate[1] - 0.005, o.translate[2]],
                                  "rotate_deg": [0, 45, 10]}) for o in _objects()]
    cache, exact = CachedRenderer(_objects()), HalfSpaceRenderer(_objects(), max_depth=1)
    before = cache.render_view(sensor, 48, 36, [light], spp=2).rgb
    assert not cache.update(_objects()) and not exact.update(_objects())
    assert cache.update(moved) and exact.update(moved)
    after = cache.render_view(sensor, 48, 36, [light], spp=2).rgb
    fresh = CachedRenderer(moved).render_view(sensor, 48, 36, [light], spp=2).rgb
    np.testing.assert_array_equal(after, fresh)
    assert np.abs(after - before).max() > 0.1 * after.max()
    reference = exact.render_view(sensor, 48, 36, [light], spp=2).rgb
    assert psnr(after, reference) > 30


def test_06_irradiance_is_kept_per_light(variant, monkeypatch):
    """A light that lit the cache before is not computed again while nothing moves; a moved object relights
    every light."""
    cache = CachedRenderer(_objects())
    point = PointLight(np.array([0.3, 0.1, -0.02]), np.array([1.0, 1.0, 1.0]))
    computed = []
    original = CachedRenderer._irradiance_of

    def counting(self, light, seed):
        computed.append(light)
        return original(self, light, seed)

    monkeypatch.setattr(CachedRenderer, "_irradiance_of", counting)
    o, d = np.array([[0.3, 0.0, -0.08]], np.float32), np.array([[-1.0, 0.0, 0.0]], np.float32)
    first = LightFieldLight(_incident(), side="synthetic", model="area")
    both = cache.render_rays(o, d, [point, first])[0]
    second = LightFieldLight(_incident(), side="synthetic", model="area")
    again = cache.render_rays(o, d, [point, second])[0]
    assert computed == [point, first, second]
    np.testing.assert_allclose(again, both, rtol=1e-5)
    cache.update([_objects()[0], _objects()[1].model_copy(update={"translate": [0.05, 0.03, -0.06]})])
    cache.render_rays(o, d, [point, second])
    assert computed[3:] == [point, second]


def test_07_auto_never_drops_light_between_synthetic_objects(variant):
    """Two reflecting synthetic objects exchange light the fast path does not render: "auto" takes the exact
    path for them, and a forced fast path says what it drops; an emitter beside one reflecting object is fine."""
    from lftransfer.scenes import builtin_scene, load_scene, with_overrides
    from lftransfer.transfer.synthetic_side import approximations, resolve_renderer

    scene = load_scene(builtin_scene("fig4"))
    cube = scene.synthetic[0].model_dump(mode="json")
    ball = {"name": "ball", "shape": "sphere", "radius": 0.01, "translate": [0.05, 0.0, -0.1]}
    two = with_overrides(scene, synthetic=[cube, ball])
    assert resolve_renderer(scene) == "fast" and resolve_renderer(two) == "exact"
    assert any("exchange with each other" in note for note in approximations(two, "fast"))
    assert approximations(two, "auto") == []
    sun = {**ball, "material": {"type": "emitter", "radiance": [1.0, 1.0, 1.0]}}
    lit = with_overrides(scene, synthetic=[cube, sun])
    assert resolve_renderer(lit) == "fast" and len(approximations(lit)) == 1
