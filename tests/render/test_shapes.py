"""Scene objects as Mitsuba shapes: they load, sit where the config says and carry the right BSDF."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lftransfer.render.shapes import bsdf_dict, object_keys, scene_dict, shape_dict
from lftransfer.scenes import GlossyMaterial, MetalMaterial, ObjectConfig, builtin_scene, load_scene


def _obj(**kw) -> ObjectConfig:
    return ObjectConfig.model_validate(kw)


@pytest.fixture()
def objects(tmp_path):
    import trimesh

    trimesh.creation.box(extents=[0.04, 0.04, 0.04]).export(tmp_path / "small.obj")
    scene = load_scene(builtin_scene("fig4"))
    return [
        *scene.real, *scene.synthetic,
        _obj(name="Ball #1", shape="sphere", radius=0.02, translate=[0.10, 0.05, 0.12],
             material={"type": "glossy", "albedo": [0.3, 0.4, 0.5], "roughness": 0.2}),
        _obj(name="can", shape="cylinder", radius=0.015, height=0.05, translate=[-0.1, 0.0, -0.12],
             rotate_deg=[90.0, 0.0, 0.0], material={"type": "metal", "specular": [0.9, 0.6, 0.3], "roughness": 0.0}),
        _obj(name="mesh", shape="mesh", file=str(tmp_path / "small.obj"), translate=[-0.1, 0.1, 0.1],
             scale=[1.0, 2.0, 1.0], material={"type": "diffuse", "albedo": [0.1, 0.2, 0.3]}),
        _obj(name="egg", shape="sphere", radius=0.01, scale=[1.0, 1.0, 2.0], translate=[0.1, -0.1, -0.1]),
        _obj(name="red block", shape="rectangle", size=[0.04, 0.02], translate=[0.0, 0.12, 0.2],
             rotate_deg=[180.0, 0.0, 0.0]),
    ]


def _cast(mi, scene, origin, direction):
    ray = mi.Ray3f(mi.Point3f(*map(float, origin)), mi.Vector3f(*map(float, direction)))
    return scene.ray_intersect(ray)


def _shape_key(mi, scene, si) -> str:
    import drjit as dr

    hit = int(np.array(dr.reinterpret_array(mi.UInt32, si.shape)).ravel()[0])
    for s in scene.shapes():
        if int(np.array(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(s))).ravel()[0]) == hit:
            return s.id()
    return ""


def _box_distance(obj, origin, direction) -> float:
    """Entry distance of a ray into a box object (slab test in the box's local frame)."""
    m = obj.to_world() @ np.diag([*(np.asarray(obj.size) / 2), 1.0])
    inv = np.linalg.inv(m)
    o = (inv @ [*origin, 1.0])[:3]
    d = inv[:3, :3] @ np.asarray(direction, float)
    with np.errstate(divide="ignore"):
        t1, t2 = (-1 - o) / d, (1 - o) / d
    return float(np.max(np.minimum(t1, t2)))


def test_keys_are_derived_from_names():
    objs = [_obj(name=n, shape="sphere", radius=1.0) for n in ("red block", "Red  Block!", "type", "", "x")
            if n] + [_obj(name="--", shape="sphere", radius=1.0)]
    assert object_keys(objs) == ["red_block", "red_block_2", "type_2", "x", "object"]
    with pytest.raises(ValueError, match="clashes"):
        scene_dict(objs[:1], extra={"red_block": {"type": "point"}})


def test_bsdf_dicts():
    assert bsdf_dict(GlossyMaterial(roughness=0.0))["type"] == "plastic"
    rough = bsdf_dict(GlossyMaterial(albedo=[0.1, 0.2, 0.3], specular=[0.5] * 3, roughness=0.3))
    assert rough["type"] == "roughplastic" and rough["alpha"] == 0.3 and rough["distribution"] == "ggx"
    assert rough["diffuse_reflectance"]["value"] == [0.1, 0.2, 0.3]
    metal = bsdf_dict(MetalMaterial(specular=[0.9, 0.8, 0.7], roughness=0.05))
    assert metal["type"] == "roughconductor" and metal["material"] == "none" and metal["alpha"] == 0.05
    assert bsdf_dict(MetalMaterial(roughness=0.0))["type"] == "conductor"


def test_scene_loads_and_rays_hit_the_right_objects(variant, objects):
    from lftransfer.backend import mitsuba

    mi = mitsuba()
    keys = object_keys(objects)
    assert keys[:2] == ["red_block", "green_cube"] and keys[-1] == "red_block_2"
    d = scene_dict(objects, extra={"light": {"type": "point", "position": [0.12, 0.22, 0.0]}})
    scene = mi.load_dict(d, optimize=False)
    assert sorted(s.id() for s in scene.shapes()) == sorted(keys)
    for key, obj in zip(keys, objects):
        lo, hi = obj.bounds()
        centre = (lo + hi) / 2
        origin = centre + [0.0, 0.0, np.sign(centre[2])]      # from outside, away from the array
        direction = np.sign(centre - origin)
        si = _cast(mi, scene, origin, direction)
        assert bool(si.is_valid()[0]), key
        assert _shape_key(mi, scene, si) == key
        t = float(np.array(si.t).ravel()[0])
        assert abs(origin[2] - (hi[2] if direction[2] < 0 else lo[2])) - 1e-6 <= t <= 1.0, key
        if obj.shape == "box":
            assert t == pytest.approx(_box_distance(obj, origin, direction), abs=1e-5), key
        if obj.shape == "sphere" and not isinstance(obj.scale, list):
            assert t == pytest.approx(1.0 - obj.radius, abs=1e-5), key
        if key == "egg":                                          # semi-axis 2 r along z, a fine icosphere
            assert t == pytest.approx(1.0 - 2 * obj.radius, abs=1e-4), key
    # exact distance to the rotated Fig. 4 block's -z face, cast from the array plane along +z
    red = objects[0]
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    for x in (-0.02, 0.0, 0.03):
        # the face z = -0.025 (local), rotated by -30 deg about y: world points satisfy z = z0 + (x * s - 0.025) / c
        si = _cast(mi, scene, [x, -0.005, 0.0], [0, 0, 1])
        assert _shape_key(mi, scene, si) == "red_block"
        assert float(np.array(si.t).ravel()[0]) == pytest.approx(red.translate[2] + (x * s - 0.025) / c, abs=1e-5)
    # and the rotated synthetic cube's +z face (normal (s, 0, c)), cast along -z
    si = _cast(mi, scene, [0.01, 0.0, 0.0], [0, 0, -1])
    assert _shape_key(mi, scene, si) == "green_cube"
    assert float(np.array(si.t).ravel()[0]) == pytest.approx(-objects[1].translate[2] - (0.03 - 0.01 * s) / c, abs=1e-5)


def test_bsdfs_of_loaded_shapes(variant, objects):
    from lftransfer.backend import mitsuba

    mi = mitsuba()
    keys = object_keys(objects)
    scene = mi.load_dict(scene_dict(objects), optimize=False)
    shapes = {s.id(): s for s in scene.shapes()}
    fig4 = {o.name: o.material.albedo for o in load_scene(builtin_scene("fig4")).real + load_scene(builtin_scene("fig4")).synthetic}
    expected = {"red_block": ("SmoothDiffuse", fig4["red block"]), "green_cube": ("SmoothDiffuse", fig4["green cube"]),
                "mesh": ("SmoothDiffuse", [0.1, 0.2, 0.3]), "egg": ("SmoothDiffuse", [0.5] * 3),
                "ball_1": ("RoughPlastic", None), "can": ("SmoothConductor", None),
                "red_block_2": ("SmoothDiffuse", None)}
    for key, obj in zip(keys, objects):
        if key not in expected:
            continue
        kind, albedo = expected[key]
        bsdf = shapes[key].bsdf()
        assert str(bsdf).startswith(kind + "["), (key, str(bsdf))
        if albedo is None:
            continue
        lo, hi = obj.bounds()
        centre = (lo + hi) / 2
        si = _cast(mi, scene, centre + [0, 0, np.sign(centre[2])], [0, 0, -np.sign(centre[2])])
        assert _shape_key(mi, scene, si) == key
        refl = np.array(si.bsdf().eval_diffuse_reflectance(si)).ravel()
        np.testing.assert_allclose(refl, albedo, atol=1e-5, err_msg=key)
    # glossy ball: the diffuse part of a plastic is the albedo; the conductor reflects its specular colour
    params = mi.traverse(shapes["ball_1"].bsdf())
    np.testing.assert_allclose(np.array(params["diffuse_reflectance.value"]).ravel(), [0.3, 0.4, 0.5], atol=1e-6)
    assert np.array(params["alpha"]).ravel()[0] == pytest.approx(0.2)
    params = mi.traverse(shapes["can"].bsdf())
    np.testing.assert_allclose(np.array(params["specular_reflectance.value"]).ravel(), [0.9, 0.6, 0.3], atol=1e-6)


def test_meshes_are_cached_by_content(variant, tmp_path, monkeypatch):
    monkeypatch.setenv("LFT_CACHE_DIR", str(tmp_path / "c"))
    a = _obj(name="a", shape="cylinder", radius=0.01, height=0.02)
    b = _obj(name="b", shape="cylinder", radius=0.01, height=0.02, translate=[1.0, 0.0, 0.0])
    c = _obj(name="c", shape="cylinder", radius=0.02, height=0.02)
    fa, fb, fc = (shape_dict(o)["filename"] for o in (a, b, c))
    assert fa == fb != fc and len(list((tmp_path / "c" / "meshes").glob("*.ply"))) == 2
    assert not list((tmp_path / "c" / "meshes").glob(".tmp-*"))


def test_render_is_sane(variant):
    """A small render through Mitsuba's own integrator: the lit face of a capped cylinder is bright, the rest dark."""
    from lftransfer.backend import mitsuba

    mi = mitsuba()
    can = _obj(name="can", shape="cylinder", radius=0.03, height=0.02, translate=[0.0, 0.0, 0.1])
    d = scene_dict([can], extra={
        "sensor": {"type": "orthographic", "to_world": mi.ScalarTransform4f().look_at(
            origin=[0, 0, 0], target=[0, 0, 1], up=[0, 1, 0]) @ mi.ScalarTransform4f().scale([0.05, 0.05, 1]),
            "film": {"type": "hdrfilm", "width": 32, "height": 32, "rfilter": {"type": "box"}},
            "sampler": {"type": "independent", "sample_count": 4}},
        "light": {"type": "point", "position": [0.0, 0.0, 0.0], "intensity": {"type": "rgb", "value": [1.0] * 3}},
        "integrator": {"type": "direct"},
    })
    image = np.array(mi.render(mi.load_dict(d, optimize=False)))[..., :3]
    centre, corner = image[16, 16], image[1, 1]
    # cap at distance 0.09 facing the light: L = I / r^2 * albedo / pi
    np.testing.assert_allclose(centre, 0.5 / np.pi / 0.09 ** 2, rtol=1e-3)
    assert np.all(corner == 0)
