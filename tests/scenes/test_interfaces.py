"""Scenes with several light field interfaces (``[[interface]]``): where objects may stand, and the errors that
say where they may not (docs/scene-format.md)."""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.rig.model import nominal_interfaces
from lftransfer.scenes import SceneError, builtin_scene, load_scene
from lftransfer.scenes.frame import scene_in_frame
from lftransfer.scenes.interfaces import facing_interfaces, interface_names, placements

BASE = """
[light]
position = [0.3, 0.12, 0.0]

[[interface]]
name = "front"

[[interface]]
name = "side"
translate = [-0.16, 0.0, 0.16]
rotate_deg = [0.0, 90.0, 0.0]
"""


def _block(name: str, at, side: str = "real") -> str:
    return f"""
[[{side}]]
name = "{name}"
shape = "box"
size = [0.04, 0.04, 0.04]
translate = [{at[0]}, {at[1]}, {at[2]}]
"""


def _load(tmp_path, text: str):
    path = tmp_path / "scene.toml"
    path.write_text(text, encoding="utf-8")
    return load_scene(path)


def test_01_two_interfaces_place_their_arrays_and_regions(tmp_path):
    scene = _load(tmp_path, BASE + _block("block", (0.0, 0.0, 0.08)) + _block("cube", (0.0, 0.0, -0.08), "synthetic")
                  + _block("lamp", (-0.22, 0.0, 0.08), "synthetic") + _block("both", (-0.25, 0.0, -0.1), "synthetic"))
    assert interface_names(scene.interfaces) == ["front", "side"]
    front, side = nominal_interfaces(scene)
    np.testing.assert_allclose(front.world_to_array(), np.eye(4))
    # the side array's middle is at (-0.16, 0, 0.16), its real side (+z in its frame) the world's +x
    m = side.world_to_array()
    np.testing.assert_allclose(m @ [-0.16, 0.0, 0.16, 1.0], [0, 0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(m[:3, :3] @ [1.0, 0.0, 0.0], [0, 0, 1], atol=1e-12)
    assert [facing_interfaces(o.bounds(), scene.interfaces) for o in scene.synthetic] == [[0], [1], [0, 1]]
    assert len(placements(scene.interfaces)) == 2 and placements([])[0].tolist() == np.eye(4).tolist()
    # moved into the side array's frame, everything keeps its place relative to the arrays
    moved = scene_in_frame(scene, m)
    np.testing.assert_allclose(moved.interfaces[1].to_world(), np.eye(4), atol=1e-12)
    assert [facing_interfaces(o.bounds(), moved.interfaces) for o in moved.synthetic] == [[0], [1], [0, 1]]


@pytest.mark.parametrize("extra, where, what", [
    (_block("block", (-0.17, 0.0, 0.08)), "real[0]",
     "a real object must lie on the real side of every interface; 'block' reaches 3 cm behind interface 'side'"),
    (_block("block", (0.0, 0.0, 0.05)) + _block("ghost", (0.0, 0.0, 0.1), "synthetic"), "synthetic[0]",
     "a synthetic object must lie wholly on the synthetic side of at least one interface; 'ghost' does not"),
])
def test_02_an_object_in_the_wrong_region_is_named_in_one_line(tmp_path, extra, where, what):
    with pytest.raises(SceneError) as err:
        _load(tmp_path, BASE + extra)
    message = str(err.value)
    assert "\n" not in message and message.startswith(f"{tmp_path / 'scene.toml'}: {where}"), message
    assert what in message, message


@pytest.mark.parametrize("text, what", [
    ("[[interface]]\nname = 'one'\n", "give two or more [[interface]] tables, or none"),
    ("[[interface]]\nname = 'a'\ntranslate = [0.1, 0, 0]\n[[interface]]\nname = 'b'\n",
     "interface[0] ('a') defines the world frame"),
    ("[[interface]]\nname = 'a'\n[[interface]]\nname = 'a'\ntranslate = [0.5, 0, 0]\n", "'a' is given more than once"),
    ("[[interface]]\nname = 'a'\n[[interface]]\nname = 'b'\nrows = 0\n", "interface[1].rows"),
])
def test_03_bad_interface_tables(tmp_path, text, what):
    with pytest.raises(SceneError, match="interface") as err:
        _load(tmp_path, "[light]\nposition = [0.3, 0.12, 0.0]\n" + text + _block("b", (0.0, 0.0, 0.1)))
    assert what in str(err.value), str(err.value)


def test_04_the_built_in_corner():
    scene = load_scene(builtin_scene("corner"))
    assert interface_names(scene.interfaces) == ["front", "side"]
    faces = {o.name: facing_interfaces(o.bounds(), scene.interfaces) for o in scene.synthetic}
    assert faces == {"green cube": [0], "lamp": [1], "grey beam": [0, 1]}
    assert scene.effect.by == "lamp" and faces[scene.effect.by] == [1]


def test_05_the_built_in_enclosure():
    scene = load_scene(builtin_scene("enclosure"))
    assert interface_names(scene.interfaces) == ["front", "side", "top"]
    faces = {o.name: facing_interfaces(o.bounds(), scene.interfaces) for o in scene.synthetic}
    assert faces == {"green cube": [0], "lamp": [1], "white panel": [2]}
    assert scene.effect.by == "lamp" and faces[scene.effect.by] == [1]
    # the top array's real side is -y, its lattice over z in [0, 0.24] m
    top = nominal_interfaces(scene)[2]
    np.testing.assert_allclose(top.world_to_array()[:3, :3] @ [0.0, -1.0, 0.0], [0, 0, 1], atol=1e-12)
