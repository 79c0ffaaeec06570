"""The fast path (irradiance cached at tessellation vertices) against the exact path, at small resolution."""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.lightfield import LightField
from lftransfer.optics import LensArray
from lftransfer.render.camera import sensor_dict
from lftransfer.render.fast import CachedRenderer, supports, tessellate
from lftransfer.render.fast.irradiance import IrradianceCache
from lftransfer.render.lights import LightFieldLight, PointLight
from lftransfer.render.renderer import HalfSpaceRenderer
from lftransfer.scenes.format import ObjectConfig
from lftransfer.sim.metrics import psnr

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


def approximations(scene, kind="auto"):
    """What the renderer ``kind`` resolves to for ``scene`` approximates there, at the scene's max_depth."""
    from lftransfer.render.selection import approximations as notes, resolve_renderer

    return notes(scene, resolve_renderer(scene, kind), max_depth=scene.render.max_depth)


def synthetic_renderer(scene):
    """The renderer a run of ``scene`` builds (settings resolved as a run resolves them)."""
    from lftransfer.render.selection import make_renderer
    from lftransfer.settings import resolve_settings

    settings = resolve_settings(scene).transfer
    return make_renderer(scene.synthetic, settings.renderer, settings.max_depth)


def test_04_glossy_and_metal_take_the_fast_path_where_verified(variant):
    """Every material renders on the fast path; "auto" takes it for glossy and metal objects of roughness at
    least MIN_ROUGHNESS (measured as accurate as the exact path), the exact path below, and a forced fast path
    says what it approximates."""
    from lftransfer.render.fast import MIN_ROUGHNESS
    from lftransfer.scenes import builtin_scene, load_scene, with_overrides
    from lftransfer.render.selection import resolve_renderer

    glossy = _objects({"type": "glossy", "albedo": [0.5] * 3, "roughness": 0.2})
    assert supports(glossy) and supports(_objects())
    assert isinstance(CachedRenderer(glossy), CachedRenderer)
    scene = load_scene(builtin_scene("fig4"))
    assert isinstance(synthetic_renderer(scene), CachedRenderer)

    def with_material(material):
        return with_overrides(scene, synthetic=[{**scene.synthetic[0].model_dump(mode="json"), "material": material}])

    assert MIN_ROUGHNESS == 0.02
    for material in ({"type": "glossy", "roughness": 0.3}, {"type": "metal", "roughness": 0.02}):
        shiny = with_material(material)
        assert resolve_renderer(shiny) == "fast" and isinstance(synthetic_renderer(shiny), CachedRenderer)
        assert any("glossy and metal lobes" in note for note in approximations(shiny))
        assert any("at the cache points towards the camera" in note
                   for note in approximations(shiny)) == (material["roughness"] >= 0.15)
    for roughness, words in ((0.01, "not verified"), (0.0, "mirror the captured light field")):
        rough = with_material({"type": "metal", "roughness": roughness})
        assert resolve_renderer(rough) == "exact" and type(synthetic_renderer(rough)) is HalfSpaceRenderer
        assert approximations(rough) == []
        assert any(words in note for note in approximations(rough, "fast"))


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
    original = IrradianceCache.irradiance_of

    def counting(self, light, seed):
        computed.append(light)
        return original(self, light, seed)

    monkeypatch.setattr(IrradianceCache, "irradiance_of", counting)
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


def test_07_auto_renders_light_between_synthetic_objects(variant):
    """Two diffuse synthetic objects light each other: "auto" takes the fast path, which renders it (test_16),
    and the report says what it leaves out; with a glossy or metal one among them too (fig6, fig1b), the report
    then naming the glossy light they exchange; an emitter beside one reflecting object exchanges nothing."""
    from lftransfer.scenes import builtin_scene, load_scene, with_overrides
    from lftransfer.render.selection import resolve_renderer

    scene = load_scene(builtin_scene("fig4"))
    cube = scene.synthetic[0].model_dump(mode="json")
    ball = {"name": "ball", "shape": "sphere", "radius": 0.01, "translate": [0.05, 0.0, -0.1]}
    two = with_overrides(scene, synthetic=[cube, ball])
    assert resolve_renderer(scene) == "fast" and resolve_renderer(two) == "fast"
    assert any("exchange: their diffuse light" in note for note in approximations(two))
    assert synthetic_renderer(two).gathers == scene.render.max_depth - 1
    assert not any("exchange" in note for note in approximations(scene))
    shiny = with_overrides(scene, synthetic=[cube, {**ball, "material": {"type": "metal", "roughness": 0.1}}])
    assert resolve_renderer(shiny) == "fast" and resolve_renderer(shiny, "exact") == "exact"
    assert any("glossy light" in n for n in approximations(shiny)) and approximations(shiny, "exact") == []
    assert resolve_renderer(load_scene(builtin_scene("fig6"))) == "fast"
    assert resolve_renderer(load_scene(builtin_scene("fig1b"))) == "fast"
    sun = {**ball, "material": {"type": "emitter", "radiance": [1.0, 1.0, 1.0]}}
    lit = with_overrides(scene, synthetic=[cube, sun])
    assert resolve_renderer(lit) == "fast" and len(approximations(lit)) == 1


def _glossy_views(material, light: str, lobes: bool = True, reference_samples: int = 256):
    """The view of the cube and ball made of ``material``, lit by the light field (area model) or the point light:
    the fast path (``lobes=False``: its diffuse cache alone), the exact path at its default 4 aperture points and
    the exact path converged (``reference_samples`` aperture points), all on the same rays."""
    from lftransfer.backend import mitsuba

    mi = mitsuba()
    sensor = mi.load_dict(sensor_dict([0.3, 0.1, 0.0], [0.0, 0.0, -0.07], [0, 1, 0], 30.0, 96, 72))

    def lights(m, seed):
        if light == "point":
            return [PointLight(np.array([0.2, 0.15, 0.0]), np.array([1.0, 0.8, 0.6]))]
        return [LightFieldLight(_incident(), "synthetic", model="area", aperture_samples=m, seed=seed)]

    exact = HalfSpaceRenderer(_objects(material), max_depth=1)
    reference = exact.render_view(sensor, 96, 72, lights(reference_samples, 9), spp=4, seed=3)
    plain = exact.render_view(sensor, 96, 72, lights(4, 0), spp=4, seed=3)
    fast = CachedRenderer(_objects(material), glossy=lobes).render_view(sensor, 96, 72, lights(4, 0), spp=4, seed=3)
    return fast.rgb, plain.rgb, reference.rgb, reference.alpha >= 1.0


def _rel(image, reference, mask):
    return float(np.abs(image[mask] - reference[mask]).sum() / np.abs(reference[mask]).sum())


# Relative error over the objects' pixels against the converged exact path, measured with
# tests/render/measure_glossy.py (fast / exact at 4 aperture points; the view's 36 multi-jittered lobe directions
# per ray, lobes of roughness >= 0.15 read from the cache points, test_17): glossy 0.034 / 0.081, 0.035 / 0.049,
# 0.035 / 0.038 at roughness 0.05, 0.1, 0.3; metal 0.042 / 0.311, 0.044 / 0.139, 0.031 / 0.045. Bounds: the
# measured error plus 50 %.
GLOSSY_BOUNDS = {("glossy", 0.05): 0.051, ("glossy", 0.1): 0.053, ("glossy", 0.3): 0.053,
                 ("metal", 0.05): 0.063, ("metal", 0.1): 0.066, ("metal", 0.3): 0.047}


@pytest.mark.parametrize("kind, roughness", sorted(GLOSSY_BOUNDS))
def test_08_glossy_lobes_under_a_light_field_match_the_exact_path(variant, kind, roughness):
    """Glossy (roughplastic) and metal (roughconductor) objects lit by a direction-dependent light field: the
    fast path is within the measured bound of the converged exact path and no worse than the exact path at its
    default samples (plus a margin for noise); the diffuse cache alone (negative control) is far worse."""
    material = {"type": kind, "roughness": roughness,
                **({"albedo": [0.3, 0.8, 0.4]} if kind == "glossy" else {"specular": [0.9, 0.7, 0.5]})}
    fast, plain, reference, mask = _glossy_views(material, "field")
    control, _, _, _ = _glossy_views(material, "field", lobes=False, reference_samples=1)
    assert reference[mask].mean() > 0.005
    error = _rel(fast, reference, mask)
    assert error < GLOSSY_BOUNDS[kind, roughness], error
    assert error < 1.3 * _rel(plain, reference, mask) + 0.01
    assert _rel(control, reference, mask) > 3 * error


@pytest.mark.parametrize("kind", ["glossy", "metal"])
def test_09_glossy_lobes_under_a_point_light_match_the_exact_path(variant, kind):
    """Under a point light the glossy lobe is the exact path's own estimate (one shadow ray per ray); what differs
    is the diffuse cache and the tessellated ball (measured 0.013 glossy, 0.007 metal at roughness 0.1)."""
    material = {"type": kind, "roughness": 0.1}
    fast, plain, reference, mask = _glossy_views(material, "point", reference_samples=1)
    control, _, _, _ = _glossy_views(material, "point", lobes=False, reference_samples=1)
    np.testing.assert_array_equal(plain, reference)          # a point light needs no aperture samples
    assert _rel(fast, reference, mask) < 0.025
    assert _rel(control, reference, mask) > 2 * _rel(fast, reference, mask)


def test_10_smooth_metal_mirrors_the_light_field(variant):
    """A mirror (metal, roughness 0) under a uniform light field: a ray whose reflection meets an aperture
    within the lenslets' window sees specular * L; one that misses the array sees nothing. The exact path
    (next-event estimation only) renders no light in a delta lobe: 0 (what approximations() says)."""
    lf = LightField.zeros(ARRAY, 8, 8)
    lf.data[...] = 2.0
    lf.data *= lf.mask()[None, :, :, None]
    light = [LightFieldLight(lf, "synthetic", model="area")]
    mirror = ObjectConfig.model_validate({"name": "mirror", "shape": "rectangle", "size": [0.3, 0.3],
                                          "translate": [0.0, 0.0, -0.05],
                                          "material": {"type": "metal", "specular": [0.9, 0.6, 0.3],
                                                       "roughness": 0.0}})
    # hits at (0.005, 0, -0.05) and (0.14, 0, -0.05), mirrored along (-0.1, 0, 1): towards (0, 0, 0), inside the
    # array (u = -0.1), and towards (0.135, 0, 0), beyond it
    d = np.array([[-0.1, 0.0, -1.0], [-0.1, 0.0, -1.0]])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    hits = np.array([[0.005, 0.0, -0.05], [0.14, 0.0, -0.05]])
    origins = hits - 0.03 * d
    fast, hit, _ = CachedRenderer([mirror]).render_rays(origins, d, light)
    assert hit.all()
    np.testing.assert_allclose(fast[0], 2.0 * np.array([0.9, 0.6, 0.3]), rtol=1e-4)
    np.testing.assert_array_equal(fast[1], 0.0)
    exact, _, _ = HalfSpaceRenderer([mirror], max_depth=1).render_rays(origins, d, light)
    np.testing.assert_array_equal(exact, 0.0)


@pytest.mark.parametrize("model", ["point", "prefiltered"])
def test_11_point_lenslets_glossy(variant, model):
    """Under the point and prefiltered models every lenslet is a point light: the fast path sums them per ray as
    the exact path does, its shadow rays replaced by the cache's visibility."""
    material = {"type": "metal", "roughness": 0.2}
    from lftransfer.backend import mitsuba

    mi = mitsuba()
    sensor = mi.load_dict(sensor_dict([0.3, 0.1, 0.0], [0.0, 0.0, -0.07], [0, 1, 0], 30.0, 96, 72))
    lights = [LightFieldLight(_incident(), "synthetic", model=model)]
    fast = CachedRenderer(_objects(material)).render_view(sensor, 96, 72, lights, spp=4)
    exact = HalfSpaceRenderer(_objects(material), max_depth=1).render_view(sensor, 96, 72, lights, spp=4)
    mask = exact.alpha >= 1.0
    assert exact.rgb[mask].mean() > 0.01
    assert _rel(fast.rgb, exact.rgb, mask) < 0.03


def test_12_lenslet_visibility_is_cached_until_objects_move(variant):
    """A blocker between a rough metal plate and the array darkens the plate's reflection alike in both paths;
    the lenslet visibility is computed once while nothing moves and again after a move."""
    from lftransfer.backend import mitsuba

    mi = mitsuba()
    plate = ObjectConfig.model_validate({"name": "plate", "shape": "rectangle", "size": [0.1, 0.1],
                                         "translate": [0.0, 0.0, -0.08], "rotate_deg": [0, 20, 0],
                                         "material": {"type": "metal", "roughness": 0.3}})
    blocker = ObjectConfig.model_validate({"name": "blocker", "shape": "sphere", "radius": 0.012,
                                           "translate": [0.0, 0.0, -0.04],
                                           "material": {"type": "emitter", "radiance": [0.0, 0.0, 0.0]}})
    sensor = mi.load_dict(sensor_dict([0.3, 0.1, 0.0], [0.0, 0.0, -0.08], [0, 1, 0], 30.0, 64, 48))
    lights = [LightFieldLight(_incident(), "synthetic", model="area")]
    fast = CachedRenderer([plate, blocker])
    blocked = fast.render_view(sensor, 64, 48, lights, spp=4)
    table = fast.lobes.visibility.tables[(ARRAY, "synthetic", None)]
    fast.render_view(sensor, 64, 48, [LightFieldLight(_incident(), "synthetic", model="area")], spp=4)
    assert fast.lobes.visibility.tables[(ARRAY, "synthetic", None)] is table
    exact = HalfSpaceRenderer([plate, blocker], max_depth=1).render_view(sensor, 64, 48, lights, spp=4)
    free = CachedRenderer([plate]).render_view(sensor, 64, 48, lights, spp=4)
    mask = (exact.alpha >= 1.0) & (exact.depth > 0.25)          # the plate, not the blocker
    assert mask.sum() > 200
    assert free.rgb[mask].sum() > 1.1 * exact.rgb[mask].sum()
    assert _rel(blocked.rgb, exact.rgb, mask) < 0.08
    assert fast.update([plate, blocker.model_copy(update={"translate": [0.0, 0.03, -0.04]})])
    assert (ARRAY, "synthetic") not in fast.lobes.visibility.tables


def test_15_shared_corners_and_moves(variant):
    """Cache vertices of one (position, normal) pair share their irradiance; a moved object is its refined local
    mesh moved (no new refinement), and the cache relit after a move is the cache of a fresh renderer."""
    from lftransfer.render.fast import tessellation

    cube, ball = _objects()
    for obj, fewer in ((cube, 5.0), (ball, 5.0)):
        cut = tessellation(obj, 0.006)
        for arr in (cut.vertices, cut.normals):        # one value per pair
            first = np.zeros((cut.distinct, 3), np.float32)
            first[cut.shared] = arr
            np.testing.assert_allclose(first[cut.shared], arr, atol=1e-6)
        assert len(cut.vertices) / cut.distinct > fewer
    # a box edge's corner is not shared across faces (the normals differ)
    cut = tessellation(cube, 0.006)
    assert cut.distinct > len(np.unique(np.round(cut.vertices, 5), axis=0))
    moved = cube.model_copy(update={"translate": [0.01, 0.02, -0.09], "rotate_deg": [10, 50, 0]})
    a, b = tessellation(cube, 0.006), tessellation(moved, 0.006)
    r0, r1 = cube.to_world(), moved.to_world()
    back = (b.vertices - r1[:3, 3]) @ np.linalg.inv(r1[:3, :3]).T @ r0[:3, :3].T + r0[:3, 3]
    np.testing.assert_allclose(back, a.vertices, atol=1e-6)
    np.testing.assert_array_equal(a.shared, b.shared)
    light = [PointLight(np.array([0.2, 0.15, 0.0]), np.array([1.0, 0.8, 0.6])), LightFieldLight(
        _incident(), side="synthetic", model="area", reconstruction="linear")]
    r = CachedRenderer(_objects())
    r.relight(light)
    r.update([moved, ball])
    r.relight(light)
    fresh = CachedRenderer([moved, ball])
    fresh.relight(light)
    for e, f in zip(r.irradiance.values, fresh.irradiance.values):
        np.testing.assert_allclose(np.array(e), np.array(f), rtol=1e-5, atol=1e-7)
    assert np.array(r.irradiance.values[0]).max() > 0


def _facing_panels(material):
    """Two panels in a V opening towards the camera, 8 cm apart, a point light between them: each is lit by the
    light and by the other (the light they exchange is about 15 % of what the camera sees)."""
    return [ObjectConfig.model_validate({"name": "left", "shape": "rectangle", "size": [0.1, 0.1],
                                         "translate": [-0.04, 0.0, -0.12], "rotate_deg": [0, 60, 0],
                                         "material": {"type": "diffuse", "albedo": [0.2, 0.9, 0.3]}}),
            ObjectConfig.model_validate({"name": "right", "shape": "box", "size": [0.1, 0.1, 0.01],
                                         "translate": [0.04, 0.0, -0.12], "rotate_deg": [0, -60, 0],
                                         "material": material})]


@pytest.mark.parametrize("material", [{"type": "diffuse", "albedo": [0.9, 0.9, 0.9]},
                                      {"type": "glossy", "albedo": [0.5, 0.5, 0.6], "roughness": 0.1}],
                         ids=["diffuse", "glossy"])
def test_16_interreflection_between_synthetic_objects(variant, material):
    """The fast path's gather renders the light two synthetic objects exchange (diffuse, and seen in a glossy
    lobe) as the converged exact path does; without its bounces (the control) that light is missing."""
    from lftransfer.backend import mitsuba

    mi = mitsuba()
    w, h = 96, 72
    sensor = mi.load_dict(sensor_dict([0.0, 0.04, 0.0], [0.0, 0.0, -0.12], [0, 1, 0], 40.0, w, h))
    light = [PointLight(np.array([0.0, 0.03, -0.09]), np.array([1.0, 1.0, 1.0]))]
    objects = _facing_panels(material)
    reference = HalfSpaceRenderer(objects, max_depth=3).render_view(sensor, w, h, light, spp=512, seed=1)
    direct = HalfSpaceRenderer(objects, max_depth=1).render_view(sensor, w, h, light, spp=64, seed=1)
    exact = HalfSpaceRenderer(objects, max_depth=3).render_view(sensor, w, h, light, spp=4)
    seen = reference.alpha > 0.99

    def error(image):
        return np.abs(image.rgb - reference.rgb)[seen].sum() / reference.rgb[seen].sum()

    share = 1.0 - direct.rgb[seen].sum() / reference.rgb[seen].sum()
    assert share > 0.1                                                       # the effect is there to miss
    with_bounces = CachedRenderer(objects, max_depth=3).render_view(sensor, w, h, light, spp=4)
    without = CachedRenderer(objects, max_depth=1).render_view(sensor, w, h, light, spp=4)
    assert error(with_bounces) < 0.04 and error(with_bounces) < error(exact)
    assert error(without) > 0.8 * share                                      # the control misses it


def test_17_view_glossy_lobes_from_the_cache_points(variant, monkeypatch):
    """A view camera's rays share one origin, so a rough lobe's radiance towards it is computed once per cache
    point (with more lobe directions) and interpolated: as accurate as sampling the lobe at every ray, here more
    (measured 0.032 against 0.043 for a metal of roughness 0.3); light field rays (many origins) sample per ray."""
    from lftransfer.render.fast import glossy as glossy_module
    from lftransfer.render.fast.glossy import GlossyLobes

    material = {"type": "metal", "roughness": 0.3, "specular": [0.9, 0.7, 0.5]}
    calls = []
    inner = GlossyLobes.pinhole

    def counted(self, *args, **kwargs):
        calls.append(args[0])
        return inner(self, *args, **kwargs)

    monkeypatch.setattr(GlossyLobes, "pinhole", counted)
    at_points, plain, reference, mask = _glossy_views(material, "field")
    assert len(calls) == 1 and np.allclose(calls[0], [0.3, 0.1, 0.0], atol=1e-6)
    monkeypatch.setattr(glossy_module, "PINHOLE_ROUGHNESS", 10.0)         # control: every lobe per ray
    per_ray, _, _, _ = _glossy_views(material, "field")
    assert len(calls) == 1
    assert _rel(at_points, reference, mask) < 0.045
    assert _rel(at_points, reference, mask) < _rel(per_ray, reference, mask) + 0.005
    renderer = CachedRenderer(_objects(material))
    lf = renderer.render_lightfield(ARRAY, [LightFieldLight(_incident(), "synthetic", model="area")], 12, 12,
                                    model="area", spp=4)
    assert lf.data.max() > 0 and len(calls) == 1                      # no pinhole for a light field


def _covered_frame():
    """A rough gold frame with a glossy photograph laid 0.5 mm in front of it (fig1b's construction): the frame's
    cache points under the photograph are buried, and the view sees into the gap under the photograph's edges."""
    rotate = [-13.0, 37.0, 0.0]
    frame = ObjectConfig.model_validate({"name": "frame", "shape": "box", "size": [0.1, 0.08, 0.01],
                                         "translate": [0.0, 0.0, -0.1], "rotate_deg": rotate,
                                         "material": {"type": "metal", "roughness": 0.08,
                                                      "specular": [0.95, 0.75, 0.35]}})
    normal = frame.to_world()[:3, :3] @ np.array([0.0, 0.0, 1.0])
    photo = ObjectConfig.model_validate({"name": "photo", "shape": "rectangle", "size": [0.06, 0.045],
                                         "translate": (np.array([0.0, 0.0, -0.1]) + 0.0055 * normal).tolist(),
                                         "rotate_deg": rotate,
                                         "material": {"type": "glossy", "albedo": [0.8, 0.8, 0.8],
                                                      "roughness": 0.04}})
    return [frame, photo]


def test_18_a_covered_surface_matches_the_exact_path(variant, monkeypatch):
    """Where one object lies on another (a photograph on its frame), the frame's cache points under it are buried:
    their values are filled from the open points beside them, hits in the gap under the edge are shaded as the
    exact path shades them, and lobes on triangles crossed by the edge cast their directions. Against the
    converged exact path the frame and photograph then match; the control (nothing filled, nothing cast) shows
    bands along the edges."""
    from lftransfer.backend import mitsuba
    from lftransfer.render.fast import visibility as visibility_module
    from lftransfer.render.fast.interreflection import Arrangement

    mi = mitsuba()
    w, h = 120, 90
    sensor = mi.load_dict(sensor_dict([0.3, 0.12, 0.0], [0.0, 0.0, -0.1], [0, 1, 0], 28.0, w, h))
    objects = _covered_frame()

    def lights(m=4, seed=0):
        return [LightFieldLight(_incident(), "synthetic", model="area", aperture_samples=m, seed=seed),
                PointLight(np.array([0.15, 0.1, 0.0]), np.array([0.3, 0.3, 0.3]))]

    reference = HalfSpaceRenderer(objects, max_depth=1).render_view(sensor, w, h, lights(256, 9), spp=16, seed=3)
    mask = reference.alpha >= 1.0
    assert mask.sum() > 2000
    fast = CachedRenderer(objects, view_lobe_samples=64).render_view(sensor, w, h, lights(), spp=16, seed=3)
    monkeypatch.setattr(visibility_module, "VARYING_VISIBILITY", 2.0)
    monkeypatch.setattr(Arrangement, "burial", lambda self: None)
    control = CachedRenderer(objects, view_lobe_samples=64).render_view(sensor, w, h, lights(), spp=16, seed=3)
    from scipy.ndimage import binary_dilation, binary_erosion

    photo = HalfSpaceRenderer(objects[1:], max_depth=1).render_view(sensor, w, h, lights(), spp=4).alpha > 0.5
    band = mask & (binary_dilation(photo, iterations=2) & ~binary_erosion(photo, iterations=2))   # the edges
    assert band.sum() > 200
    # measured: over the edge band 0.0063 against the control's 0.0214; over both objects 0.0028 / 0.0061
    assert _rel(fast.rgb, reference.rgb, band) < 0.01 and _rel(control.rgb, reference.rgb, band) > 0.015
    assert _rel(fast.rgb, reference.rgb, mask) < 0.005


def test_19_objects_that_move_as_one_keep_their_gather(variant):
    """Objects keyframed apart but moving as one (fig1b's photograph and frame drift by 0.01 mm) keep their
    interreflection gather and buried points; the drift is measured from the arrangement the gather was cast for,
    so it cannot add up unseen; a real move between them (1 mm) casts it again."""
    from lftransfer.render.fast.interreflection import TOGETHER

    objects = _facing_panels({"type": "diffuse", "albedo": [0.9, 0.9, 0.9]})
    light = [PointLight(np.array([0.0, 0.03, -0.09]), np.array([1.0, 1.0, 1.0]))]
    r = CachedRenderer(objects, max_depth=3)
    r.relight(light)
    gather = r.arrangement.gather()

    def moved(dx_left, dx_right):
        return [o.model_copy(update={"translate": (np.array(o.translate) + [dx, 0.01, 0.0]).tolist()})
                for o, dx in zip(objects, (dx_left, dx_right))]

    steps = [moved(0.0, 0.00004 * i) for i in range(1, 4)]       # 0.04 mm more drift each step
    assert r.update(steps[0]) and r.arrangement.gather() is gather
    assert r.update(steps[1]) and r.arrangement.gather() is gather            # 0.08 mm from the gather's arrangement
    assert r.update(steps[2]) and r.arrangement.gather() is not gather        # 0.12 mm > TOGETHER
    assert TOGETHER == pytest.approx(1e-4)
    gather = r.arrangement.gather()
    assert r.update(moved(0.001, 0.0)) and r.arrangement.gather() is not gather


@pytest.mark.parametrize("hits", [0, 1, 57, 4000])
def test_20_group_means_from_the_hits_equal_the_full_size_means(hits):
    """The fast path's per-pixel means, summed over the groups with a hit only, equal the means over every ray
    (rays that miss count as black; depth is the mean over the hits, inf where none hit)."""
    from lftransfer.render.fast import group_means

    rng = np.random.default_rng(hits)
    spp, groups = 4, 2500
    idx = np.sort(rng.choice(groups * spp, hits, replace=False))
    colour = rng.random((hits, 3)).astype(np.float32)
    t = rng.uniform(0.05, 0.5, hits).astype(np.float32)
    full = np.zeros((groups * spp, 3))
    full[idx] = colour
    hit = np.zeros(groups * spp)
    hit[idx] = 1.0
    dist = np.zeros(groups * spp)
    dist[idx] = t
    means = group_means(idx, colour, t, groups, spp)
    np.testing.assert_allclose(means.radiance, full.reshape(groups, spp, 3).mean(1), rtol=1e-6, atol=0)
    count = hit.reshape(groups, spp).sum(1)
    np.testing.assert_array_equal(means.coverage, count / spp)
    with np.errstate(invalid="ignore", divide="ignore"):
        expected = np.where(count > 0, dist.reshape(groups, spp).sum(1) / count, np.inf)
    np.testing.assert_allclose(means.depth, expected, rtol=1e-6)
    assert means.radiance.dtype == means.coverage.dtype == means.depth.dtype == np.float32


def test_where_the_tessellation_shows_the_run_says_so():
    """A curved synthetic object on which a cache triangle spans several view pixels (Fig. 5's planet: about 14 at
    the paper's resolution) gets a warning naming it and --renderer exact; a cube (flat faces), the same planet
    seen from six times as far, and the exact path get none."""
    from lftransfer.render.selection import visible_steps
    from lftransfer.scenes import builtin_scene, load_scene, with_overrides

    fig5 = load_scene(builtin_scene("fig5"))
    (note,) = visible_steps(fig5, "fast")
    assert "'planet'" in note and "--renderer exact" in note and "about 14 pixels" in note
    assert visible_steps(fig5, "exact") == [] and visible_steps(load_scene(builtin_scene("fig4")), "fast") == []
    origin = np.asarray(fig5.view.origin, float)
    planet = next(o for o in fig5.synthetic if o.name == "planet")
    far = origin + 6 * (np.asarray(planet.translate, float) - origin)
    moved = [{**o.model_dump(mode="json"), "translate": list(far) if o.name == "planet" else o.translate,
              "keyframes": []} for o in fig5.synthetic]
    assert not any("'planet'" in n for n in visible_steps(with_overrides(fig5, synthetic=moved), "fast"))
