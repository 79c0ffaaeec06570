"""Albedo textures: the exact path (Mitsuba's bitmap through shapes.py) and the fast path (the texture read per
ray at the hit's texture coordinates, times the cached irradiance / pi) against the analytic value per texel and
against each other."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lftransfer.render.camera import sensor_dict
from lftransfer.render.fast import CachedRenderer
from lftransfer.render.lights import PointLight
from lftransfer.render.renderer import HalfSpaceRenderer
from lftransfer.scenes.format import ObjectConfig, read_texture
from lftransfer.sim.metrics import psnr

# Image rows top to bottom: the top row lies along the rectangle's local +y edge (the image appears upright seen
# from the rectangle's front with +y up).
TWO_BY_TWO = [[[230, 40, 40], [40, 200, 60]],
              [[50, 60, 220], [240, 230, 30]]]


def _png(path: Path, pixels) -> Path:
    from PIL import Image

    Image.fromarray(np.asarray(pixels, np.uint8)).save(path)
    return path


def _random_image(path: Path, size: int = 8, seed: int = 0) -> Path:
    return _png(path, np.random.default_rng(seed).integers(20, 255, (size, size, 3)))


def _board(texture: Path, material: str = "diffuse", **extra) -> ObjectConfig:
    mat = {"type": material, "albedo": [1.0, 1.0, 1.0], "texture": str(texture), **extra}
    return ObjectConfig.model_validate({"name": "board", "shape": "rectangle", "size": [0.08, 0.06],
                                        "translate": [0.0, 0.0, -0.1], "material": mat})


def test_01_rectangle_texels_match_the_analytic_value(variant, tmp_path):
    """A two-by-two texture under a point light straight above: at each texel's centre both paths give
    texel / pi * I cos / r^2, with the image's top row on the rectangle's +y side."""
    board = _board(_png(tmp_path / "four.png", TWO_BY_TWO))
    linear = read_texture(board.material.texture)                  # (2, 2, 3), row 0 = top
    light = PointLight(np.array([0.0, 0.0, -0.02]), np.array([1.0, 1.0, 1.0]))
    # texel (row, col) centre: x = (col - 0.5) * 0.04, y = (0.5 - row) * 0.03
    rows, cols = np.meshgrid([0, 1], [0, 1], indexing="ij")
    x, y = (cols.ravel() - 0.5) * 0.04, (0.5 - rows.ravel()) * 0.03
    targets = np.stack([x, y, np.full(4, -0.1)], axis=1)
    origins = targets + [0.0, 0.0, 0.05]
    directions = np.tile([0.0, 0.0, -1.0], (4, 1))
    r2 = (x**2 + y**2 + 0.08**2)
    expected = linear[rows.ravel(), cols.ravel()] / np.pi * (0.08 / np.sqrt(r2) / r2)[:, None]
    for renderer in (HalfSpaceRenderer([board], max_depth=1), CachedRenderer([board])):
        radiance, hit, _ = renderer.render_rays(origins, directions, [light])
        assert hit.all()
        # the cache interpolates the irradiance linearly across 6 mm triangles: within 0.5 % here
        np.testing.assert_allclose(radiance, expected, rtol=5e-3 if isinstance(renderer, CachedRenderer) else 1e-4)
    # negative control: without the texture the four texels are alike
    plain = CachedRenderer([board.model_copy(update={"material": board.material.model_copy(
        update={"texture": None})})]).render_rays(origins, directions, [light])[0]
    assert np.ptp(plain[:, 0] / expected[:, 0]) > 1.0


def _views(objects, lights, size=(96, 72), spp=4):
    from lftransfer.backend import mitsuba

    mi = mitsuba()
    sensor = mi.load_dict(sensor_dict([0.3, 0.1, 0.0], [0.0, 0.0, -0.08], [0, 1, 0], 30.0, *size))
    fast = CachedRenderer(objects).render_view(sensor, *size, lights, spp=spp)
    exact = HalfSpaceRenderer(objects, max_depth=1).render_view(sensor, *size, lights, spp=spp)
    return fast, exact


@pytest.mark.parametrize("shape", ["rectangle", "box", "sphere"])
def test_02_fast_path_reads_the_shapes_texture_coordinates(variant, tmp_path, shape):
    """Textured rectangle, box (Mitsuba's cube, one image per face) and sphere (u around the axis, seam at local
    +x, which the camera sees): the fast path's texture coordinates follow the exact shapes'."""
    texture = _random_image(tmp_path / "noise.png")
    geometry = {"rectangle": {"size": [0.08, 0.06], "rotate_deg": [0, 60, 0]},
                "box": {"size": [0.05] * 3, "rotate_deg": [0, 30, 0]},
                "sphere": {"radius": 0.03, "rotate_deg": [0, 0, 20]}}[shape]
    obj = ObjectConfig.model_validate({"name": "o", "shape": shape, "translate": [0.0, 0.0, -0.08], **geometry,
                                       "material": {"albedo": [1.0, 1.0, 1.0], "texture": str(texture)}})
    light = [PointLight(np.array([0.25, 0.1, 0.0]), np.array([1.0, 1.0, 1.0]))]
    fast, exact = _views([obj], light)
    plain, _ = _views([obj.model_copy(update={"material": obj.material.model_copy(update={"texture": None})})],
                      light)
    mask = exact.alpha >= 1.0
    assert mask.sum() > 300
    assert psnr(fast.rgb, exact.rgb, mask=mask) > 33, shape
    assert psnr(plain.rgb, exact.rgb, mask=mask) < psnr(fast.rgb, exact.rgb, mask=mask) - 8   # negative control


def test_03_glossy_texture(variant, tmp_path):
    """The texture multiplies a glossy material's diffuse albedo in both paths; the coating stays white."""
    board = _board(_random_image(tmp_path / "noise.png", seed=1), "glossy", roughness=0.2)
    board = board.model_copy(update={"rotate_deg": [0.0, 60.0, 0.0]})
    fast, exact = _views([board], [PointLight(np.array([0.25, 0.1, 0.0]), np.array([1.0, 1.0, 1.0]))])
    mask = exact.alpha >= 1.0
    assert psnr(fast.rgb, exact.rgb, mask=mask) > 33
