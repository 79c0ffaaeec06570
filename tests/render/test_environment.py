"""The room's light as an environment map (lftransfer.render.lights.EnvironmentLight).

A diffuse plate (albedo 0.5) under a uniform room of radiance L = 2, rendered through the half-space renderer.

What each test shows:
- test_01: facing the room, the plate sends back albedo x L (1.0) to 1.5 %: importance-sampled directions with
  shadow rays give the irradiance pi L. A plate whose only view of the room is blocked by a second plate gets
  nothing from it (the shadow rays).
- test_02: on the synthetic side, 8 cm behind a large array, facing it: the array blocks exactly the directions
  its lenslets record (|u|, |v| <= a = 0.5), the projected solid angle 4 X, X = (a / sqrt(1 + a^2))
  atan(a / sqrt(1 + a^2)) = 0.188, so the plate sends albedo L (pi - 4 X) / pi (0.380 of its unblocked value
  less). Negative controls: blocking every direction through the rectangle leaves almost nothing; no blocker,
  albedo x L.
- test_03: rays that leave the scene see the map along their direction (a map with one lit texel: the texel's
  direction sees it, others see black), nothing when the light is hidden, nothing where the array blocks them.
- test_04: the irradiance a plane facing any direction receives from the whole map (its cosine-weighted sum) is
  pi L for a uniform room, and a rotation turns the map's directions into the renderer's frame.
"""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.optics.geometry import env_directions
from lftransfer.render.lights import EnvironmentLight
from lftransfer.render.renderer import HalfSpaceRenderer
from lftransfer.scenes.objects import RealObject

L = 2.0
ALBEDO = 0.5
N = 4000


def _plate(z: float, normal_z: float = 1.0, name: str = "plate", size: float = 0.2):
    # a rectangle's front faces +z; turned half a turn about x it faces -z
    return RealObject.model_validate({"name": name, "shape": "rectangle", "size": [size, size],
                                      "translate": [0.0, 0.0, z], "rotate_deg": [0.0 if normal_z > 0 else 180.0, 0, 0],
                                      "material": {"type": "diffuse", "albedo": [ALBEDO] * 3}})


def _seen(objects, origin, direction, lights, seed: int = 0) -> np.ndarray:
    r = HalfSpaceRenderer(objects, max_depth=1)
    o = np.tile(np.asarray(origin, np.float32), (N, 1))
    d = np.tile(np.asarray(direction, np.float32) / np.linalg.norm(direction), (N, 1))
    radiance, hit, _ = r.render_rays(o, d, lights, seed=seed)
    return radiance, hit


def _uniform(**kw) -> EnvironmentLight:
    return EnvironmentLight(np.full((32, 64, 3), L, np.float32), **kw)


def test_01_a_plate_in_a_uniform_room(variant):
    radiance, hit = _seen([_plate(0.1)], (0, 0, 0.5), (0, 0, -1), [_uniform()])
    assert hit.all()
    assert np.allclose(radiance.mean(0), ALBEDO * L, rtol=0.015), radiance.mean(0)
    # a second, larger plate right above hides the whole room from the first one's centre
    cover = _plate(0.102, normal_z=-1.0, name="cover", size=2.0)
    shaded, _ = _seen([_plate(0.1, size=0.02), cover], (0, 0, 0.101), (0, 0, -1), [_uniform()])
    assert shaded.mean() < 0.02 * ALBEDO * L


def test_02_the_array_blocks_what_its_lenslets_record(variant):
    a = 0.5
    x = a / np.sqrt(1 + a * a) * np.arctan(a / np.sqrt(1 + a * a))
    expected = ALBEDO * L * (np.pi - 4 * x) / np.pi
    plate = _plate(-0.08, size=0.02)
    eye = (0, 0, -0.5)
    radiance, _ = _seen([plate], (0.0, 0.0, -0.079), (0, 0, -1), [])       # nothing: no light
    assert radiance.max() == 0
    lit, _ = _seen([plate], (0.0, 0.0, -0.079), (0, 0, -1), [_uniform(blocker=(-1, 1, -1, 1), window=a)])
    assert lit.mean() == pytest.approx(expected, rel=0.02), (lit.mean(), expected)
    # negative controls: the whole rectangle blocks nearly everything; no blocker blocks nothing
    dark, _ = _seen([plate], (0.0, 0.0, -0.079), (0, 0, -1), [_uniform(blocker=(-1, 1, -1, 1))])
    assert dark.mean() < 0.01 * ALBEDO * L
    full, _ = _seen([plate], (0.0, 0.0, -0.079), (0, 0, -1), [_uniform()])
    assert full.mean() == pytest.approx(ALBEDO * L, rel=0.015)
    assert eye  # the camera stands behind the plate's back: the rays start just in front of it


def test_03_rays_that_leave_see_the_room(variant):
    img = np.zeros((16, 32, 3), np.float32)
    img[5, 21] = 7.0
    d = env_directions(32, 16)
    room = EnvironmentLight(img)
    along = d[5, 21].astype(np.float32)
    elsewhere = d[12, 3].astype(np.float32)
    o = np.zeros((2, 3), np.float32)
    seen = room.background(o, np.stack([along, elsewhere]))
    assert seen[0] == pytest.approx([7.0] * 3, rel=1e-4) and np.all(seen[1] == 0)
    assert np.all(room.hidden().background(o, np.stack([along, elsewhere])) == 0)
    # through the trace: a ray that meets nothing sees the map; a hidden light's does not
    r = HalfSpaceRenderer([_plate(0.1)], max_depth=1)
    radiance, hit, _ = r.render_rays(np.array([[0, 0, 0.5]], np.float32), along[None], [room])
    assert not hit[0] and radiance[0] == pytest.approx([7.0] * 3, rel=1e-4)
    radiance, _, _ = r.render_rays(np.array([[0, 0, 0.5]], np.float32), along[None], [room.hidden()])
    assert np.all(radiance == 0)
    # from the synthetic side, a ray through the array inside the lenslets' window is the array's to carry
    up = np.array([[0.0, 0.0, 1.0]], np.float32)
    flat = EnvironmentLight(np.full((16, 32, 3), 3.0, np.float32), blocker=(-1, 1, -1, 1), window=0.5)
    assert np.all(flat.background(np.array([[0, 0, -0.1]], np.float32), up) == 0)
    assert flat.background(np.array([[0, 0, 0.1]], np.float32), up)[0] == pytest.approx([3.0] * 3)


def test_04_irradiance_and_rotation(variant):
    room = _uniform()
    for n in ([0, 0, 1], [1, 0, 0], [0.3, -0.5, 0.8]):
        assert room.irradiance_towards(n) == pytest.approx([np.pi * L] * 3, rel=1e-3)
    img = np.zeros((32, 64, 3), np.float32)
    img[8, 40] = 1.0
    d = env_directions(64, 32)[8, 40]
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])     # 90 degrees about z
    turned = EnvironmentLight(img, turn)
    seen = turned.background(np.zeros((2, 3), np.float32), np.stack([turn @ d, d]).astype(np.float32))
    assert seen[0, 0] == pytest.approx(1.0, rel=1e-4) and seen[1, 0] == 0
    with pytest.raises(ValueError, match=r"\(H, 2H, 3\)"):
        EnvironmentLight(np.ones((32, 32, 3), np.float32))
