"""Albedo textures in scene files: paths relative to the scene file, images that must exist and decode, shapes
that must have texture coordinates; every error a SceneError naming the scene file and the field."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lftransfer.scenes import SceneError, load_scene, with_overrides
from lftransfer.scenes.format import read_texture

HEAD = "[light]\nposition = [0.1, 0.2, 0.0]\n"


def _scene(tmp_path: Path, shape: str, material: str, name: str = "scene.toml") -> Path:
    geometry = {"rectangle": "size = [0.1, 0.1]", "box": "size = [0.1, 0.1, 0.1]", "sphere": "radius = 0.05",
                "cylinder": "radius = 0.05\nheight = 0.1"}[shape]
    text = (HEAD + f"[[synthetic]]\nname = 'board'\nshape = '{shape}'\n{geometry}\ntranslate = [0.0, 0.0, -0.2]\n"
            f"[synthetic.material]\n{material}\n")
    path = tmp_path / name
    path.write_text(text)
    return path


def _png(path: Path, pixels) -> Path:
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.asarray(pixels, np.uint8)).save(path)
    return path


def _error(path: Path) -> str:
    with pytest.raises(SceneError) as info:
        load_scene(path)
    return str(info.value)


def test_01_relative_texture_resolves_against_the_scene_file(tmp_path):
    _png(tmp_path / "images" / "two.png", [[[255, 0, 0], [0, 0, 255]]])
    scene = load_scene(_scene(tmp_path, "rectangle", "albedo = [1.0, 1.0, 1.0]\ntexture = 'images/two.png'"))
    texture = scene.synthetic[0].material.texture
    assert texture == (tmp_path / "images" / "two.png").resolve() and texture.is_absolute()
    # a copy of the scene validates again with the absolute path, wherever it is run from
    again = with_overrides(scene, view={"fov_deg": 30.0})
    assert again.synthetic[0].material.texture == texture


def test_02_read_texture_decodes_srgb_to_linear(tmp_path):
    path = _png(tmp_path / "t.png", [[[0, 128, 255], [10, 10, 10]]])
    rgb = read_texture(path)
    assert rgb.shape == (1, 2, 3) and rgb.dtype == np.float32 and not rgb.flags.writeable
    np.testing.assert_allclose(rgb[0, 0], [0.0, ((128 / 255 + 0.055) / 1.055) ** 2.4, 1.0], rtol=1e-6)
    np.testing.assert_allclose(rgb[0, 1], [10 / 255 / 12.92] * 3, rtol=1e-6)   # the linear toe of the curve


def test_03_glossy_takes_a_texture_too(tmp_path):
    _png(tmp_path / "t.png", [[[200, 100, 50]]])
    scene = load_scene(_scene(tmp_path, "sphere", "type = 'glossy'\nroughness = 0.2\ntexture = 't.png'"))
    assert scene.synthetic[0].material.texture.name == "t.png"


@pytest.mark.parametrize("material, field, words", [
    ("texture = 'nowhere.png'", "synthetic[0].material.texture", "texture file does not exist"),
    ("texture = 'notes.png'", "synthetic[0].material.texture", "cannot read an image"),
    ("texture = 3", "synthetic[0].material.texture", "expected an image file path"),
    ("type = 'metal'\ntexture = 't.png'", "synthetic[0].material", "texture"),
    ("type = 'emitter'\ntexture = 't.png'", "synthetic[0].material", "texture"),
])
def test_04_bad_textures_name_the_file_and_the_field(tmp_path, material, field, words):
    (tmp_path / "notes.png").write_text("not an image")
    _png(tmp_path / "t.png", [[[1, 2, 3]]])
    path = _scene(tmp_path, "rectangle", material)
    message = _error(path)
    assert str(path) in message and field in message and words in message, message
    if "nowhere" in material:
        assert str(tmp_path / "nowhere.png") in message


def test_05_a_texture_needs_texture_coordinates(tmp_path):
    _png(tmp_path / "t.png", [[[1, 2, 3]]])
    message = _error(_scene(tmp_path, "cylinder", "texture = 't.png'"))
    assert "synthetic[0].material" in message and "texture coordinates" in message and "cylinder" in message
    for shape in ("rectangle", "box", "sphere"):
        assert load_scene(_scene(tmp_path, shape, "texture = 't.png'")).synthetic[0].material.texture is not None
    text = _scene(tmp_path, "sphere", "texture = 't.png'").read_text().replace("radius = 0.05",
                                                                             "radius = 0.05\nscale = [1.0, 2.0, 1.0]")
    (tmp_path / "ellipsoid.toml").write_text(text)
    message = _error(tmp_path / "ellipsoid.toml")
    assert "synthetic[0].material" in message and "uniformly scaled sphere" in message
