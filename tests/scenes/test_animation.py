"""Keyframed objects: interpolation, posing, validation of the [animation] table."""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.scenes import SceneError, builtin_scene, load_scene, with_overrides
from lftransfer.scenes.animation import frame_times, interpolate
from lftransfer.scenes.frame import scene_in_frame
from lftransfer.optics.geometry import rotation_xy


def test_01_linear_and_smooth_curves():
    """Linear: constant velocity; smooth: through every key, zero velocity at the ends, Catmull-Rom inside;
    both hold the end keys outside the keyed range."""
    t = np.array([0.0, 1.0, 3.0])
    v = np.array([[0.0], [1.0], [5.0]])
    assert interpolate(t, v, 0.5, "linear")[0] == pytest.approx(0.5)
    assert interpolate(t, v, 2.0, "linear")[0] == pytest.approx(3.0)
    for mode in ("linear", "smooth"):
        for ti, vi in zip(t, v):
            assert interpolate(t, v, ti, mode)[0] == pytest.approx(vi[0])
        assert interpolate(t, v, -1.0, mode)[0] == 0.0 and interpolate(t, v, 9.0, mode)[0] == 5.0
    h = 1e-5
    velocity = lambda x: (interpolate(t, v, x + h, "smooth")[0] - interpolate(t, v, x - h, "smooth")[0]) / (2 * h)  # noqa: E731
    assert abs(velocity(h)) < 1e-3 and abs(velocity(3.0 - h)) < 1e-3       # eases in and out
    assert velocity(1.0) == pytest.approx((5.0 - 0.0) / 3.0, rel=1e-4)     # Catmull-Rom tangent at the inner key
    two = interpolate(np.array([0.0, 1.0]), np.array([[0.0], [1.0]]), 0.25, "smooth")[0]
    assert two == pytest.approx(3 * 0.25**2 - 2 * 0.25**3)                  # smoothstep between two keys
    with pytest.raises(ValueError, match="increase"):
        interpolate(np.array([0.0, 0.0]), np.zeros((2, 1)), 0.0)


def test_02_frame_times():
    assert len(frame_times(2.0, 24)) == 48 and frame_times(2.0, 24)[-1] == pytest.approx(47 / 24)
    assert frame_times(0.01, 24).tolist() == [0.0]


def _animated(**obj_changes):
    scene = load_scene(builtin_scene("fig4"))
    cube = scene.synthetic[0].model_dump()
    x, y, z = cube["translate"]
    cube.update({"keyframes": [{"time_s": 0.0}, {"time_s": 1.0, "translate": [x + 0.04, y, z], "rotate_deg": [0, 0, 20]}],
                 **obj_changes})
    return scene, with_overrides(scene, animation={"duration_s": 1.0, "fps": 10}, synthetic=[cube])


def test_03_posing_keeps_unkeyed_fields():
    """A key that leaves a field out has the object's own value there; at() drops the keyframes."""
    still, scene = _animated()
    own = still.synthetic[0]
    assert scene.moving and not still.moving
    start, end, mid = scene.at(0.0).synthetic[0], scene.at(1.0).synthetic[0], scene.at(0.5).synthetic[0]
    assert start.translate == pytest.approx(own.translate) and start.rotate_deg == pytest.approx(own.rotate_deg)
    assert end.translate[0] == pytest.approx(own.translate[0] + 0.04)
    assert mid.translate[0] == pytest.approx(own.translate[0] + 0.02) and not mid.keyframes
    assert mid.scale == own.scale                                       # scale is keyed nowhere
    assert scene.frame_times().tolist() == pytest.approx(np.arange(10) / 10)
    assert scene.synthetic_part().at(0.5).synthetic[0].translate == pytest.approx(mid.translate)


def test_04_frame_change_commutes_with_posing_at_keys():
    _, scene = _animated()
    m = np.eye(4)
    m[:3, :3] = rotation_xy((0.01, -0.02))
    m[:3, 3] = [0.002, -0.001, 0.003]
    for t in (0.0, 1.0):
        a = scene_in_frame(scene, m).at(t).synthetic[0].to_world()
        b = scene_in_frame(scene.at(t), m).synthetic[0].to_world()
        np.testing.assert_allclose(a, b, atol=1e-12)


@pytest.mark.parametrize("change, message", [
    ({"keyframes": [{"time_s": 0.5}, {"time_s": 0.5}]},
     r"synthetic\[0\]\.keyframes \(of 'green cube'\): .*increase strictly"),
    ({"keyframes": [{"time_s": 0.0}, {"time_s": 2.0}]}, r"time_s 2\.0 is after the end of the animation"),
    ({"keyframes": [{"time_s": 0.0}, {"time_s": 1.0, "translate": [0.0, 0.0, 0.05]}]},
     r"synthetic\[0\]: a synthetic object must lie in z < 0; 'green cube' spans .* at t = 0\.\d+ s"),
    ({"keyframes": [{"time_s": 0.0, "scale": 0.0}]}, r"scale must be positive"),
])
def test_05_bad_keyframes_name_the_field(change, message):
    with pytest.raises(SceneError, match=message):
        _animated(**change)


def test_06_keyframes_need_an_animation_table(tmp_path):
    text = builtin_scene("fig4").read_text()
    text += '\n[[synthetic.keyframes]]\ntime_s = 0.0\n'
    path = tmp_path / "moving.toml"
    path.write_text(text)
    with pytest.raises(SceneError, match=r"moving\.toml: .*synthetic\[0\] \('green cube'\) has keyframes, but the "
                                         r"scene has no \[animation\] table"):
        load_scene(path)
    path.write_text(text + '\n[[synthetic.keyframes]]\ntime_s = 0.5\ntranslate = [0.0, 0.0, -0.1]\n'
                    '\n[animation]\nduration_s = 0.5\nfps = 4\n')
    scene = load_scene(path)
    assert scene.moving and scene.at(0.5).synthetic[0].translate == pytest.approx([0.0, 0.0, -0.1])


@pytest.mark.parametrize("table, message", [
    ('kind = "shadow"\non = "green cube"\nby = "red block"', r"effect\.on: expected the name of one \[\[real\]\] "
                                                             r"object \('red block'\), found 'green cube'"),
    ('kind = "reflection"\non = "red block"\nby = "sun"', r"effect\.by: .*found 'sun'"),
    ('kind = "glow"\non = "red block"\nby = "green cube"', r"effect\.kind"),
    ('kind = "shadow"\non = "red block"', r"effect\.by"),
])
def test_07_effect_table_names_objects(tmp_path, table, message):
    """[effect] names one real object (on) and one synthetic object (by); errors name the field."""
    path = tmp_path / "effect.toml"
    path.write_text(builtin_scene("fig4").read_text() + f"\n[effect]\n{table}\n")
    with pytest.raises(SceneError, match=r"effect\.toml: .*" + message):
        load_scene(path)
    path.write_text(builtin_scene("fig4").read_text() + '\n[effect]\nkind = "reflection"\non = "red block"\n'
                    'by = "green cube"\n')
    scene = load_scene(path)
    assert scene.effect.on == "red block" and not hasattr(scene.synthetic_part(), "effect")


def test_08_paper_scenes_load_and_move():
    """fig5, fig6 and fig1b load (meshes and textures ship with the package) and their effect objects move."""
    for name, kind in (("fig5", "shadow"), ("fig6", "reflection"), ("fig1b", None)):
        scene = load_scene(builtin_scene(name))
        assert scene.moving and scene.animation is not None
        if kind is None:
            assert scene.effect is None
            continue
        by = next(o for o in scene.synthetic if o.name == scene.effect.by)
        assert scene.effect.kind == kind and by.moves
        assert by.at(0.0).translate != by.at(scene.animation.duration_s).translate
