"""Light field lights and renders of an interface standing anywhere (docs/architecture.md, "Several interfaces"):
a rigid motion of everything changes nothing, and the windows cut exactly the rays that cross an array."""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.lightfield import LightField
from lftransfer.optics import LensArray
from lftransfer.optics.geometry import rotation_matrix
from lftransfer.render.lights import LightFieldLight
from lftransfer.render.renderer import HalfSpaceRenderer
from lftransfer.render.windows import Windows
from lftransfer.scenes.format import ObjectConfig
from lftransfer.scenes.frame import scene_in_frame  # noqa: F401  (the same frame change the pipeline uses)

ARRAY = LensArray(lattice="hex", rows=3, cols=4, pitch=0.0254, focal_length=0.0254)
U = 8


def _motion() -> np.ndarray:
    """A rigid motion that turns the array's frame well away from the world's."""
    m = np.eye(4)
    m[:3, :3] = rotation_matrix([20.0, 75.0, -30.0])
    m[:3, 3] = [-0.13, 0.04, 0.21]
    return m


def _objects(m: np.ndarray, side: str) -> list[ObjectConfig]:
    """A tilted box and a sphere on ``side`` of the array, moved by ``m``."""
    sign = -1.0 if side == "synthetic" else 1.0
    out = []
    for spec in ({"name": "box", "shape": "box", "size": [0.06, 0.05, 0.04], "translate": [0.01, -0.01, sign * 0.07],
                  "rotate_deg": [10.0, 30.0, 0.0]},
                 {"name": "ball", "shape": "sphere", "radius": 0.02, "translate": [-0.05, 0.03, sign * 0.05]}):
        to_world = m @ np.block([[rotation_matrix(spec.get("rotate_deg", [0, 0, 0])),
                                  np.array(spec["translate"])[:, None]], [np.zeros((1, 3)), np.ones((1, 1))]])
        from scipy.spatial.transform import Rotation

        moved = {**spec, "translate": to_world[:3, 3].tolist(),
                 "rotate_deg": Rotation.from_matrix(to_world[:3, :3]).as_euler("xyz", degrees=True).tolist(),
                 "material": {"type": "diffuse", "albedo": [0.7, 0.5, 0.3]}}
        out.append(ObjectConfig.model_validate(moved))
    return out


def _table(seed: int = 3) -> LightField:
    lf = LightField.zeros(ARRAY, U, U)
    lf.data[...] = np.random.default_rng(seed).uniform(0.2, 2.0, lf.data.shape) * lf.mask()[None, :, :, None]
    return lf


def _rays(m: np.ndarray, side: str) -> tuple[np.ndarray, np.ndarray]:
    """Rays from points around the objects towards them, in the array's frame moved by ``m``."""
    rng = np.random.default_rng(5)
    sign = -1.0 if side == "synthetic" else 1.0
    targets = np.column_stack([rng.uniform(-0.06, 0.04, 400), rng.uniform(-0.03, 0.04, 400), np.full(400, sign * 0.06)])
    origins = targets - np.array([0.0, 0.0, sign * 0.05]) + rng.normal(0, 0.01, (400, 3))   # on the array's side
    d = targets - origins
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return origins @ m[:3, :3].T + m[:3, 3], d @ m[:3, :3].T


def test_01_a_posed_light_lights_a_moved_scene_as_before(variant):
    """The same objects, rays and light field table, all moved by one rigid motion (the light by its pose): every
    ray's radiance is the same, for the exact path's area model with the edge window and linear reconstruction
    (synthetic side) and a projector's box light (real side)."""
    m = _motion()
    for side, kwargs in (("synthetic", {"reconstruction": "linear", "window": "edge"}),
                         ("real", {"reconstruction": "box", "window": "cut"})):
        lf = _table()
        results = []
        for motion in (np.eye(4), m):
            renderer = HalfSpaceRenderer(_objects(motion, side), max_depth=1)
            light = LightFieldLight(lf, side=side, model="area", aperture_samples=8, seed=2, pose=motion, **kwargs)
            radiance, hit, _ = renderer.render_rays(*_rays(motion, side), [light], seed=1)
            results.append((radiance, hit))
        assert results[0][1].sum() > 200
        np.testing.assert_array_equal(results[0][1], results[1][1])
        lit = results[0][0][results[0][1]]
        assert lit.mean() > 0.01
        np.testing.assert_allclose(results[1][0][results[1][1]], lit, rtol=2e-3, atol=2e-4 * lit.max())


def test_02_a_posed_light_field_render_sees_the_moved_scene(variant):
    """The light field an array receives from the synthetic side is the same when array and objects move
    together (``render_lightfield(pose=...)``), and differs when only the objects move (negative control)."""
    from lftransfer.render.lights import PointLight

    m = _motion()
    out = []
    for objects_at, array_at in ((np.eye(4), np.eye(4)), (m, m), (m, np.eye(4))):
        light = PointLight(objects_at[:3, :3] @ np.array([0.1, 0.1, -0.02]) + objects_at[:3, 3], np.full(3, 0.05))
        renderer = HalfSpaceRenderer(_objects(objects_at, "synthetic"), max_depth=1)
        out.append(renderer.render_lightfield(ARRAY, [light], U, U, spp=2, seed=4,
                                              pose=None if array_at is np.eye(4) else array_at).data)
    assert out[0].max() > 0
    np.testing.assert_allclose(out[1], out[0], rtol=2e-3, atol=1e-4 * out[0].max())
    assert np.abs(out[2] - out[0]).max() > 0.5 * out[0].max()


def test_03_windows_cut_the_rays_that_cross_an_array():
    """A ray crosses a window when it meets the array's rectangle before its end; NumPy and Dr.Jit agree."""
    m = _motion()
    windows = Windows.of([ARRAY], [m])
    x0, x1, y0, y1 = ARRAY.extent()
    rng = np.random.default_rng(0)
    local_o = np.column_stack([rng.uniform(-0.1, 0.1, (2000, 2)), rng.uniform(-0.05, 0.05, 2000)])
    local_d = rng.normal(size=(2000, 3))
    local_d /= np.linalg.norm(local_d, axis=1, keepdims=True)
    reach = rng.uniform(0.01, 0.3, 2000)
    t = -local_o[:, 2] / local_d[:, 2]
    q = local_o + t[:, None] * local_d
    expected = (t > 0) & (t < reach) & (q[:, 0] >= x0) & (q[:, 0] <= x1) & (q[:, 1] >= y0) & (q[:, 1] <= y1)
    o, d = local_o @ m[:3, :3].T + m[:3, 3], local_d @ m[:3, :3].T
    got = windows.crossed(o, d, reach)
    assert 100 < expected.sum() < 1900
    np.testing.assert_array_equal(got, expected)


def test_04_windows_in_drjit_agree(variant):
    from lftransfer.backend import mitsuba
    from lftransfer.render.lights import jit_array, jit_rays

    mi = mitsuba()
    m = _motion()
    windows = Windows.of([ARRAY], [m])
    rng = np.random.default_rng(1)
    o = np.column_stack([rng.uniform(-0.1, 0.1, (3000, 2)), rng.uniform(-0.1, 0.1, 3000)]) @ m[:3, :3].T + m[:3, 3]
    d = rng.normal(size=(3000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    reach = rng.uniform(0.01, 0.4, 3000)
    ray = jit_rays(o, d)
    got = np.array(windows.crossed_jit(ray, jit_array(mi.Float, reach.astype(np.float32))), bool)
    expected = windows.crossed(o.astype(np.float32).astype(np.float64), d.astype(np.float32).astype(np.float64),
                               reach.astype(np.float32).astype(np.float64))
    assert expected.sum() > 150
    assert (got != expected).sum() <= 2          # float32 against float64 at a rectangle's edge


@pytest.mark.parametrize("kind", ["exact", "fast"])
@pytest.mark.parametrize("lamp_faces", [1.0, -1.0], ids=["reflected", "emitted"])
def test_05_light_between_synthetic_objects_that_crosses_an_array_is_cut(variant, kind, lamp_faces):
    """A lamp above an array and a plate below it, which sees the lamp (emitted: the lamp faces it) or a plate above
    the lamp lit by it (reflected: the lamp faces away) only through the array: without windows the plate below
    receives that light, with the array as a window nothing (the rig carries it), in both renderers."""
    from lftransfer.render.lights import EmitterLight
    from lftransfer.render.selection import make_renderer

    def plate(name, z, faces, material, size=(0.08, 0.06)):
        turn = [0.0 if faces > 0 else 180.0, 0.0, 0.0]              # a rectangle's front faces +z
        return ObjectConfig.model_validate({"name": name, "shape": "rectangle", "size": list(size),
                                            "translate": [0.0, 0.0, z], "rotate_deg": turn, "material": material})

    diffuse = {"type": "diffuse", "albedo": [0.8, 0.8, 0.8]}
    objects = [plate("above", 0.06, -1.0, diffuse),
               plate("lamp", 0.02, lamp_faces, {"type": "emitter", "radiance": [30.0, 30.0, 30.0]}, (0.02, 0.02)),
               plate("below", -0.06, 1.0, diffuse)]                       # sees the others through the array only
    windows = Windows.of([ARRAY], [np.eye(4)])
    origins = np.column_stack([np.linspace(-0.03, 0.03, 50), np.zeros(50), np.full(50, -0.03)])
    directions = np.tile([0.0, 0.0, -1.0], (50, 1))                       # at the plate below, from the array's side
    seen = {}
    for cut in (None, windows):
        renderer = make_renderer(objects, kind, 2, cut)
        radiance, hit, _ = renderer.render_rays(origins, directions, [EmitterLight(seed=1, windows=cut)], seed=3)
        assert hit.all()
        seen[cut is not None] = radiance
    assert seen[False].mean() > 0.01
    assert np.abs(seen[True]).max() == 0.0
