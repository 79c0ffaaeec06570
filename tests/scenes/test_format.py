"""The scene format: the Fig. 4 file, transforms and bounds, and errors that name the file and the field."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lftransfer.scenes import (
    DiffuseMaterial,
    GlossyMaterial,
    ObjectConfig,
    SceneConfig,
    SceneError,
    builtin_scene,
    load_scene,
    with_overrides,
)

LIGHT = "[light]\nposition = [0.1, 0.2, 0.0]\n"
PROBE = "[light]\nkind = 'probe'\nball_centre = [0.28, 0.1, 0.05]\n"
BOX = "[[real]]\nname = 'a'\nshape = 'box'\nsize = [0.1, 0.1, 0.1]\ntranslate = [0.0, 0.0, 0.2]\n"


def _write(tmp_path: Path, text: str, name: str = "scene.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _error(tmp_path: Path, text: str, name: str = "bad_scene.toml") -> str:
    path = _write(tmp_path, text, name)
    with pytest.raises(SceneError) as info:
        load_scene(path)
    return str(info.value)


def _obj(**kw) -> ObjectConfig:
    return ObjectConfig.model_validate({"name": "o", **kw})


# ---------------------------------------------------------------------------------------------------------------
# The Fig. 4 scene

def test_fig4_loads_with_the_values_written():
    scene = load_scene(builtin_scene("fig4"))
    assert scene.source == builtin_scene().resolve()
    rig = scene.rig
    assert (rig.lattice, rig.rows, rig.cols, rig.aperture) == ("hex", 10, 12, "cell")
    assert rig.pitch == pytest.approx(0.0254) and rig.focal_length == pytest.approx(0.0254)
    assert rig.lf_camera == [2048, 1536] and rig.projector == [1024, 768]
    assert (rig.angular_samples, rig.lf_camera_bits, rig.projector_bits) == (48, 12, 8)
    assert rig.projector_gamma == [2.2] * 3 and rig.full_well == 20000
    assert scene.view.origin == [0.55, 0.22, 0.0] and scene.view.fov_deg == 35.0
    assert scene.render.lighting_model == "area" and scene.render.gt_spp >= 256
    (red,), (green,) = scene.real, scene.synthetic
    assert red.name == "red block" and red.shape == "box" and green.name == "green cube" and green.shape == "box"
    assert isinstance(red.material, DiffuseMaterial) and isinstance(green.material, DiffuseMaterial)
    r, g = np.asarray(red.material.albedo), np.asarray(green.material.albedo)
    assert r[0] > r[1] and r[0] > r[2] and g[1] > g[0] and g[1] > g[2]     # a red block and a green cube
    assert red.bounds()[0, 2] > 0 and green.bounds()[1, 2] < 0               # on either side of the array


def test_fig4_keeps_the_exchange_inside_the_lenslet_window():
    """Weighted by form factor, almost all light that the two objects exchange crosses the plane inside the
    array and within the lenslets' angular window |u|, |v| <= a (docs/architecture.md, "Radiometry of a lenslet")."""
    import trimesh

    from lftransfer.optics import LensArray

    scene = load_scene(builtin_scene("fig4"))
    samples = []
    for obj in (scene.real[0], scene.synthetic[0]):
        mesh = trimesh.creation.box(extents=obj.size, transform=obj.to_world())
        p, face = trimesh.sample.sample_surface(mesh, 1200, seed=1)
        samples.append((p, mesh.face_normals[face]))
    (pa, na), (pb, nb) = samples
    d = pb[None] - pa[:, None]                                   # real point -> synthetic point
    r2 = (d ** 2).sum(-1)
    dn = d / np.sqrt(r2)[..., None]
    cos_a, cos_b = (dn * na[:, None]).sum(-1), -(dn * nb[None]).sum(-1)
    weight = np.where((cos_a > 0) & (cos_b > 0), cos_a * cos_b / r2, 0.0)
    u, v = dn[..., 0] / -dn[..., 2], dn[..., 1] / -dn[..., 2]
    crossing = pa[:, None, :2] + (pa[:, None, 2] / -d[..., 2])[..., None] * d[..., :2]
    rig = scene.rig
    array = LensArray(lattice=rig.lattice, rows=rig.rows, cols=rig.cols, pitch=rig.pitch, focal_length=rig.focal_length)
    a = array.half_width
    inside = (np.abs(u) <= a) & (np.abs(v) <= a) & (array.lenslet_at(crossing) >= 0)
    assert weight.sum() > 0
    assert (weight * inside).sum() / weight.sum() > 0.95


def test_defaults_equal_the_documented_values(tmp_path):
    scene = load_scene(_write(tmp_path, LIGHT + BOX))
    fig4 = load_scene(builtin_scene())
    assert scene.rig == fig4.rig and scene.view == fig4.view and scene.render == fig4.render
    assert scene.synthetic == [] and scene.real[0].material == DiffuseMaterial(albedo=[0.5, 0.5, 0.5])


# ---------------------------------------------------------------------------------------------------------------
# Transforms and bounds

def test_to_world_order_scale_rotate_translate():
    obj = _obj(shape="box", size=[0.1, 0.2, 0.3], translate=[1.0, 2.0, 3.0], rotate_deg=[90.0, 0.0, 90.0],
               scale=[2.0, 1.0, 1.0])
    m = obj.to_world()
    assert m.shape == (4, 4) and m.dtype == np.float64
    # local corner (0.05, 0.1, 0.15): scale -> (0.1, 0.1, 0.15); Rx(90) -> (0.1, -0.15, 0.1);
    # Rz(90) -> (0.15, 0.1, 0.1); translate -> (1.15, 2.1, 3.1).
    corner = m @ np.array([0.05, 0.1, 0.15, 1.0])
    np.testing.assert_allclose(corner[:3], [1.15, 2.1, 3.1], atol=1e-12)
    np.testing.assert_allclose(m[3], [0, 0, 0, 1])


def test_bounds_of_rotated_box():
    obj = _obj(shape="box", size=[0.08, 0.06, 0.05], translate=[0.0, -0.005, 0.10], rotate_deg=[0.0, -30.0, 0.0])
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    hx, hz = 0.04 * c + 0.025 * s, 0.04 * s + 0.025 * c
    np.testing.assert_allclose(obj.bounds(), [[-hx, -0.035, 0.10 - hz], [hx, 0.025, 0.10 + hz]], atol=1e-12)
    # every corner lies inside, and some corner touches each face of the box
    corners = np.array([[x, y, z, 1] for x in (-0.04, 0.04) for y in (-0.03, 0.03) for z in (-0.025, 0.025)])
    w = (obj.to_world() @ corners.T).T[:, :3]
    np.testing.assert_allclose([w.min(0), w.max(0)], obj.bounds(), atol=1e-12)


def test_bounds_of_sphere_and_ellipsoid():
    ball = _obj(shape="sphere", radius=0.03, translate=[0.1, 0.2, 0.3], rotate_deg=[10.0, 20.0, 30.0])
    np.testing.assert_allclose(ball.bounds(), [[0.07, 0.17, 0.27], [0.13, 0.23, 0.33]], atol=1e-12)
    egg = _obj(shape="sphere", radius=1.0, scale=[2.0, 1.0, 1.0], rotate_deg=[0.0, 0.0, 90.0])
    np.testing.assert_allclose(egg.bounds(), [[-1, -2, -1], [1, 2, 1]], atol=1e-12)


def test_bounds_of_rotated_cylinder():
    upright = _obj(shape="cylinder", radius=0.02, height=0.1, translate=[0.0, 0.0, 0.5])
    np.testing.assert_allclose(upright.bounds(), [[-0.02, -0.02, 0.45], [0.02, 0.02, 0.55]], atol=1e-12)
    tilted = _obj(shape="cylinder", radius=0.02, height=0.1, rotate_deg=[45.0, 0.0, 0.0])
    e = 0.05 * math.sqrt(0.5) + 0.02 * math.sqrt(0.5)
    np.testing.assert_allclose(tilted.bounds(), [[-0.02, -e, -e], [0.02, e, e]], atol=1e-12)
    # the analytic box contains the facetted mesh and is tight to it
    v, _ = tilted.triangle_mesh()
    w = v @ tilted.to_world()[:3, :3].T
    assert np.all(w.min(0) >= tilted.bounds()[0] - 1e-12) and np.all(w.max(0) <= tilted.bounds()[1] + 1e-12)
    np.testing.assert_allclose([w.min(0), w.max(0)], tilted.bounds(), atol=2e-5)


def test_mesh_path_relative_to_scene_file_and_bounds(tmp_path):
    import trimesh

    (tmp_path / "meshes").mkdir()
    trimesh.creation.box(extents=[0.02, 0.04, 0.06]).export(tmp_path / "meshes" / "b.obj")
    text = LIGHT + "[[synthetic]]\nname = 'm'\nshape = 'mesh'\nfile = 'meshes/b.obj'\ntranslate = [0, 0, -0.1]\n"
    scene = load_scene(_write(tmp_path, text))
    obj = scene.synthetic[0]
    assert obj.file == (tmp_path / "meshes" / "b.obj").resolve()
    np.testing.assert_allclose(obj.bounds(), [[-0.01, -0.02, -0.13], [0.01, 0.02, -0.07]], atol=1e-9)


def test_light_field_rays_per_entry_default_to_spp():
    """``render.lf_spp`` sets the outgoing light field's rays per entry (fig5 takes 16); unset, it is ``spp``;
    the view keeps ``spp`` either way."""
    from lftransfer.settings import resolve_settings

    fig4, fig5 = (load_scene(builtin_scene(name)) for name in ("fig4", "fig5"))
    assert fig4.render.lf_spp is None
    assert (resolve_settings(fig4).transfer.lf_spp, resolve_settings(fig4).transfer.view_spp) == (4, 4)
    assert (resolve_settings(fig5).transfer.lf_spp, resolve_settings(fig5).transfer.view_spp) == (16, 4)
    more = with_overrides(fig4, render={"spp": 8})
    assert resolve_settings(more).transfer.lf_spp == 8


def test_with_overrides_revalidates():
    scene = load_scene(builtin_scene())
    small = with_overrides(scene, view={"resolution": [64, 48]}, render={"gt_spp": 8})
    assert small.view.resolution == [64, 48] and small.view.fov_deg == 35.0 and small.render.gt_spp == 8
    assert scene.view.resolution == [1024, 768]
    with pytest.raises(SceneError, match=r"fig4\.toml: view\.resolution\[0\]"):
        with_overrides(scene, view={"resolution": [0, 48]})
    with pytest.raises(SceneError, match=r"synthetic\[0\]: a synthetic object must lie in z < 0"):
        with_overrides(scene, synthetic=[scene.real[0]])


# ---------------------------------------------------------------------------------------------------------------
# Errors: one SceneError naming the file and the field path

@pytest.mark.parametrize("text, path, what", [
    (LIGHT + BOX + "colour = 1\n", "real[0].colour", "unknown key"),
    (LIGHT + "[rig]\nrows = 'ten'\n" + BOX, "rig.rows", "expected a number"),
    (LIGHT + "[view]\nfov_deg = [35]\n" + BOX, "view.fov_deg", "found [35]"),
    (LIGHT + BOX.replace("[0.1, 0.1, 0.1]", "[0.1, -0.1, 0.1]"), "real[0].size[1]", "greater than 0"),
    (LIGHT + BOX + "[real.material]\nalbedo = [0.5, 1.2, 0.5]\n", "real[0].material.albedo[1]",
     "less than or equal to 1"),
    (LIGHT + BOX + "[real.material]\ntype = 'glossy'\nroughness = 1.5\n", "real[0].material.roughness",
     "less than or equal to 1"),
    (LIGHT + BOX + "[real.material]\nalbedo = [0.5, 0.5]\n", "real[0].material.albedo", "at least 3"),
    (LIGHT + BOX + "[real.material]\ntype = 'plastic'\n", "real[0].material", "plastic"),
    (LIGHT + BOX.replace("size = [0.1, 0.1, 0.1]\n", ""), "real[0].size", "a box needs 'size'"),
    (LIGHT + BOX.replace("[0.1, 0.1, 0.1]", "[0.1, 0.1]"), "real[0].size", "3 components"),
    (LIGHT + BOX + "radius = 0.1\n", "real[0].radius", "does not apply to a box"),
    (LIGHT + "[[real]]\nname = 'm'\nshape = 'mesh'\nfile = 'nope.obj'\ntranslate = [0, 0, 0.2]\n",
     "real[0].file", "does not exist"),
    (LIGHT + BOX.replace("[0.0, 0.0, 0.2]", "[0.0, 0.0, 0.04]"), "real[0]", "must lie in z > 0"),
    (LIGHT + BOX + "[[synthetic]]\nname = 's'\nshape = 'sphere'\nradius = 0.05\ntranslate = [0, 0, -0.04]\n",
     "synthetic[0]", "must lie in z < 0"),
    (LIGHT + BOX + "[real.material]\ntype = 'emitter'\nradiance = [1, 1, 1]\n", "real[0]",
     "an emitter is a synthetic object"),
    (LIGHT + BOX + "[[synthetic]]\nname = 's'\nshape = 'sphere'\nradius = 0.01\ntranslate = [0, 0, -0.1]\n"
     "[synthetic.material]\ntype = 'emitter'\nradiance = [1, -1, 1]\n", "synthetic[0].material.radiance[1]",
     "greater than or equal to 0"),
    (LIGHT + BOX + "scale = [1, 2]\n", "real[0].scale", "1 or 3 components"),
    (LIGHT + BOX + "scale = -1\n", "real[0].scale", "positive"),
    (LIGHT, "synthetic", "at least one"),
    (BOX, "<scene>", "nothing lights the scene: give a [light] table"),
    (LIGHT + "[rig]\nlattice = 'square'\n" + BOX, "rig.lattice", "'hex' or 'rect'"),
    (LIGHT + "[view]\ntarget = [0.55, 0.22, 0.0]\n" + BOX, "view.target", "must differ from origin"),
    (LIGHT + BOX + "source = 'x'\n", "real[0].source", "unknown key"),
    (LIGHT + "[rig]\nrows = 10\n[[real]\nname = 'a'\n", "<toml>", "malformed TOML"),
    ("[[light]]\nposition = [0.1, 0.2, 0.0]\n[[light]]\nposition = [0.1, 0.2]\n" + BOX, "light[1].position",
     "at least 3"),
    ("[[light]]\nposition = [0.1, 0.2, 0.0]\n" * 9 + BOX, "light", "at most 8"),
    (LIGHT + "[render]\nprojection = 'prefilter'\n" + BOX, "render.projection", "'box', 'depth' or 'solve'"),
    (LIGHT + "[render]\nlf_spp = 0\n" + BOX, "render.lf_spp", "greater than 0"),
    (PROBE.replace("0.05]", "-0.05]") + BOX, "probe.ball_centre", "the ball stands among the real objects"),
    (PROBE.replace("[light]", "[[light]]") + LIGHT.replace("[light]", "[[light]]") + BOX, "<scene>",
     "a light probe is the scene's only direct light"),
    (PROBE + BOX + "[environment]\nfile = 'room.exr'\n", "environment.file", "does not exist"),
    (PROBE + BOX + "[environment]\nsun_direction = [0, 0, 0]\n", "environment.sun_direction", "zero vector"),
    (PROBE + BOX + "[environment]\nwidth = 33\n", "environment.width", "multiple of 2"),
])
def test_bad_input_names_file_and_field(tmp_path, text, path, what):
    """The file, the field path (with the object's name where the field is inside a named object) and what was
    expected."""
    import re

    message = _error(tmp_path, text)
    assert re.match(rf"{re.escape(str(tmp_path / 'bad_scene.toml'))}: {re.escape(path)}( \(of '[a-z0-9_]+'\))?: ",
                    message), message
    assert what in message, message


def test_an_unknown_key_names_its_object_and_the_closest_key(tmp_path):
    """A misspelt key gets the closest key of its table (nothing where none is close) and the object it sits in;
    ``[lights]``, the model's own name for the lights, is refused in a file (the table is [light])."""
    message = _error(tmp_path, LIGHT + BOX + "[real.material]\nalbdo = [0.5, 0.5, 0.5]\n")
    assert "real[0].material.albdo (of 'a'): unknown key" in message and "did you mean 'albedo'?" in message
    message = _error(tmp_path, LIGHT + BOX.replace("translate", "transalte"))
    assert "did you mean 'translate'?" in message
    assert "did you mean" not in _error(tmp_path, LIGHT + BOX + "colour = 1\n")
    message = _error(tmp_path, LIGHT.replace("[light]", "[lights]") + BOX)
    assert message.startswith(f"{tmp_path / 'bad_scene.toml'}: lights: unknown key") and "'light'" in message
    message = _error(tmp_path, LIGHT + "[render]\ngt_sp = 4\n" + BOX)
    assert "render.gt_sp: unknown key" in message and "did you mean 'gt_spp'?" in message


def test_one_error_summarises_the_others(tmp_path):
    message = _error(tmp_path, LIGHT + BOX + "colour = 1\n[rig]\nrows = 0\n")
    assert message.count("bad_scene.toml") == 1 and "rig.rows" in message and "real[0].colour" in message
    assert "and 1 more" in message


def test_missing_file_and_unknown_builtin(tmp_path):
    with pytest.raises(SceneError, match="nothing.toml: cannot read"):
        load_scene(tmp_path / "nothing.toml")
    with pytest.raises(SceneError, match="available: .*fig4, fig5"):
        builtin_scene("fig99")


def test_one_light_or_several(tmp_path):
    """``[light]`` is one point light, ``[[light]]`` several, in the file's order; ``lights`` holds them either way
    and survives :func:`with_overrides`."""
    one = load_scene(_write(tmp_path, LIGHT + BOX))
    assert [lt.position for lt in one.lights] == [[0.1, 0.2, 0.0]]
    text = "[[light]]\nposition = [0.1, 0.2, 0.0]\n[[light]]\nposition = [-0.1, 0.2, 0.0]\nintensity = [2, 2, 2]\n"
    two = load_scene(_write(tmp_path, text + BOX, "two.toml"))
    assert [lt.position for lt in two.lights] == [[0.1, 0.2, 0.0], [-0.1, 0.2, 0.0]]
    assert two.lights[1].intensity == [2.0, 2.0, 2.0] and two.synthetic_part().lights == two.lights
    assert with_overrides(two, view={"fov_deg": 30.0}).lights == two.lights
    assert with_overrides(two, lights=two.lights[:1]).lights == one.lights


def test_model_validate_applies_the_same_rules():
    with pytest.raises(ValueError, match="must lie in z > 0"):
        SceneConfig.model_validate({"light": {"position": [0, 0, 0]},
                                    "real": [{"name": "x", "shape": "sphere", "radius": 0.1}]})


# ---------------------------------------------------------------------------------------------------------------
# Property test: material ranges

_finite = st.floats(min_value=-10, max_value=10, allow_nan=False)


@settings(max_examples=40, deadline=None)
@given(albedo=st.lists(_finite, min_size=3, max_size=3), roughness=_finite,
       kind=st.sampled_from(["diffuse", "glossy", "metal"]))
def test_material_ranges(tmp_path_factory, albedo, roughness, kind):
    lines = [f"type = '{kind}'"]
    if kind != "metal":
        lines.append(f"albedo = [{', '.join(repr(a) for a in albedo)}]")
    else:
        lines.append(f"specular = [{', '.join(repr(a) for a in albedo)}]")
    if kind != "diffuse":
        lines.append(f"roughness = {roughness!r}")
    text = LIGHT + BOX + "[real.material]\n" + "\n".join(lines) + "\n"
    path = _write(tmp_path_factory.mktemp("h"), text)
    valid = all(0 <= a <= 1 for a in albedo) and (kind == "diffuse" or 0 <= roughness <= 1)
    if valid:
        material = load_scene(path).real[0].material
        assert material.type == kind
        if kind == "glossy":
            assert isinstance(material, GlossyMaterial) and material.roughness == roughness
    else:
        with pytest.raises(SceneError) as info:
            load_scene(path)
        assert str(info.value).startswith(f"{path}: real[0].material.")


def test_the_light_probe_and_its_room(tmp_path, variant):
    """``[light] kind = "probe"`` is the light probe, apart from the point lights (the scene has none); it is part
    of what the pipeline knows, the ``[environment]`` (the room) is not; the scene's frame moves the ball; the room
    is a sky with a sun, or an equirectangular EXR next to the scene file (one twice as wide as high)."""
    from lftransfer.backend import mitsuba
    from lftransfer.scenes.frame import scene_in_frame

    scene = load_scene(_write(tmp_path, PROBE + BOX + "[environment]\nsun_direction = [0, 1, 0]\nwidth = 64\n"))
    assert scene.lights == [] and scene.probe.ball_centre == [0.28, 0.1, 0.05] and scene.probe.ball_radius == 0.025
    part = scene.synthetic_part()
    assert part.probe == scene.probe and not hasattr(part, "environment")
    shift = np.eye(4)
    shift[:3, 3] = [0.0, 0.0, 0.01]
    assert scene_in_frame(scene, shift).probe.ball_centre == pytest.approx([0.28, 0.1, 0.06])
    room = scene.environment.radiance_map()
    assert room.shape == (32, 64, 3) and np.argmax(room.sum(-1)[:, 0]) == 0        # the sun at the zenith
    mitsuba().Bitmap(np.full((8, 16, 3), 0.5, np.float32)).write(str(tmp_path / "room.exr"))
    lit = load_scene(_write(tmp_path, PROBE + BOX + "[environment]\nfile = 'room.exr'\n", "file.toml"))
    assert lit.environment.radiance_map().shape == (8, 16, 3) and lit.environment.file.is_absolute()
    mitsuba().Bitmap(np.full((8, 8, 3), 0.5, np.float32)).write(str(tmp_path / "square.exr"))
    message = _error(tmp_path, PROBE + BOX + "[environment]\nfile = 'square.exr'\n")
    assert "environment.file" in message and "twice as wide as high" in message
