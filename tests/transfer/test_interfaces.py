"""The exchange through several light field interfaces (docs/architecture.md, "Several interfaces"), on tiny
simulated rigs without sensor noise."""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.rig.model import nominal_interfaces, nominal_rig
from lftransfer.scenes import SceneConfig
from lftransfer.sim.interfaces import SimInterfaces
from lftransfer.sim.rig import SimRig
from lftransfer.transfer.bounce import TransferSettings, run_transfer
from lftransfer.transfer.interfaces import run_interfaces

PITCH = 0.0254
QUIET = {"read_noise": 0.0, "full_well": 1e12, "angular_samples": 8}


def _scene(rig: dict, *, interfaces=(), real=(), synthetic=(), light=(0.3, 0.12, 0.0), view=None) -> SceneConfig:
    return SceneConfig.model_validate({
        "rig": {**QUIET, **rig}, "interface": list(interfaces), "real": list(real), "synthetic": list(synthetic),
        "light": {"position": list(light), "intensity": [2.0, 2.0, 2.0]},
        "view": view or {"resolution": [64, 48], "origin": [0.55, 0.22, 0.0], "target": [0.0, 0.0, 0.0]},
        "render": {"spp": 2, "max_depth": 1}})


def _box(name, at, size=(0.06, 0.05, 0.05), albedo=(0.8, 0.4, 0.3), turn=(0.0, -30.0, 0.0)):
    return {"name": name, "shape": "box", "size": list(size), "translate": list(at), "rotate_deg": list(turn),
            "material": {"type": "diffuse", "albedo": list(albedo)}}


SETTINGS = TransferSettings(bounces=2, angular_samples=8, reconstruction="box", window="cut", projection="box",
                            renderer="exact", max_depth=1, lf_spp=4, view_spp=4, seed=0)


def _cross(result) -> np.ndarray:
    return result.composite() - result.composite_direct()


def test_01_two_interfaces_side_by_side_are_one_of_their_extent(variant):
    """Two 3 x 4 arrays side by side in one plane exchange what one 3 x 8 array over both exchanges, the objects
    in front of the seam between them; through the left array alone the exchange is far from it (negative
    control)."""
    shift = 2 * PITCH          # the 3 x 8 array's middle, in the two arrays' frame (the left one's middle at 0)
    objects = {"real": [_box("block", (shift + 0.0, -0.005, 0.07))],
               "synthetic": [_box("cube", (shift + 0.0, 0.0, -0.07), albedo=(0.3, 0.85, 0.35), turn=(0, 30, 0))]}
    view = {"resolution": [64, 48], "origin": [shift + 0.45, 0.2, 0.0], "target": [shift, 0.0, 0.0]}
    two = _scene({"rows": 3, "cols": 4, "lf_camera": [160, 120], "projector": [80, 60]},
                 interfaces=[{"name": "left"}, {"name": "right", "translate": [4 * PITCH, 0.0, 0.0]}],
                 light=(shift + 0.3, 0.12, 0.0), view=view, **objects)
    left, right = nominal_interfaces(two)
    one = _scene({"rows": 3, "cols": 8, "lf_camera": [320, 120], "projector": [160, 60]},
                 real=[_box("block", (0.0, -0.005, 0.07))],
                 synthetic=[_box("cube", (0.0, 0.0, -0.07), albedo=(0.3, 0.85, 0.35), turn=(0, 30, 0))],
                 view={"resolution": [64, 48], "origin": [0.45, 0.2, 0.0], "target": [0.0, 0.0, 0.0]})
    combined = nominal_rig(one.rig)
    # the two lattices are the combined one's, moved by the shift
    both = np.concatenate([left.array.centres, right.array.centres + [4 * PITCH, 0.0]])
    np.testing.assert_allclose(np.sort(both[:, 0] - shift), np.sort(combined.array.centres[:, 0]), atol=1e-9)

    world = SimInterfaces(two, capture_spp=8)
    through_both = run_interfaces(world.rigs, [left, right], two.synthetic_part(), SETTINGS)
    through_left = run_interfaces(world.rigs, [left, right], two.synthetic_part(), SETTINGS, through=[0])
    single = run_transfer(SimRig(one, capture_spp=8), combined, one.synthetic_part(), SETTINGS)
    again = run_transfer(SimRig(one, capture_spp=8, seed=5), combined, one.synthetic_part(), SETTINGS)
    reference = _cross(single)
    size = np.linalg.norm(reference)
    assert size > 0.01 * np.linalg.norm(single.composite())       # the exchange is a visible part of the frame
    # the simulation's own Monte Carlo noise: the one array's exchange with the LF camera's other samples
    noise = np.linalg.norm(_cross(again) - reference) / size
    assert np.linalg.norm(_cross(through_both) - reference) / size < 1.5 * noise
    assert np.linalg.norm(_cross(through_left) - reference) / size > 3 * noise


def _corner(*, lamp: bool = False) -> SceneConfig:
    """The corner of two tiny arrays: "front" in z = 0, "side" in x = -0.06 facing +x; a block between them, a
    cube behind "front", a ball behind "side" only."""
    ball = {"name": "ball", "shape": "sphere", "radius": 0.02, "translate": [-0.12, 0.0, 0.06],
            "material": {"type": "emitter", "radiance": [1.0, 2.0, 4.0]} if lamp
            else {"type": "diffuse", "albedo": [0.5, 0.5, 0.9]}}
    return _scene({"rows": 3, "cols": 4, "lf_camera": [160, 120], "projector": [80, 60]},
                  interfaces=[{"name": "front"},
                              {"name": "side", "translate": [-0.055, 0.0, 0.055], "rotate_deg": [0.0, 90.0, 0.0]}],
                  real=[_box("block", (0.0, 0.0, 0.06), size=(0.04, 0.04, 0.04), turn=(0.0, 20.0, 0.0))],
                  synthetic=[_box("cube", (0.0, 0.0, -0.06), size=(0.04, 0.04, 0.04), albedo=(0.3, 0.85, 0.35)),
                             ball],
                  light=(0.02, 0.15, 0.02),
                  view={"resolution": [64, 48], "origin": [0.1, 0.3, 0.2], "target": [-0.04, 0.0, 0.02],
                        "fov_deg": 60.0})


def test_02_an_object_seen_through_the_second_interface_only_is_lit_by_it_only(variant):
    """The ball behind "side" receives the block's light through it; with "side" switched off it receives none
    (the cube behind "front" still does)."""
    from lftransfer.sim.ground_truth import view_distances

    scene = _corner()
    models = nominal_interfaces(scene)
    world = SimInterfaces(scene, capture_spp=2)
    ball = np.isfinite(view_distances([o for o in scene.synthetic if o.name == "ball"], scene.view))
    cube = np.isfinite(view_distances([o for o in scene.synthetic if o.name == "cube"], scene.view))
    assert ball.sum() > 20 and cube.sum() > 20
    lit = {}
    for through in ([0, 1], [0]):
        result = run_interfaces(world.rigs, models, scene.synthetic_part(), SETTINGS, through=through)
        exchanged = result.synthetic_view.rgb - result.bounces[0].synthetic_view.rgb
        lit[len(through)] = exchanged[ball].sum(), exchanged[cube].sum()
    assert lit[2][0] > 0.02 * lit[2][1] > 0
    assert lit[1][0] == 0.0 and lit[1][1] > 0


def test_03_an_lf_camera_sees_the_projector_of_the_interface_it_faces(variant):
    """Two arrays facing each other across 0.3 m of empty real space: the first one's LF camera records the
    second one's projector where its rays meet the second array's lenslets, and nothing while it is dark."""
    far = {"name": "far", "translate": [0.0, 0.0, 0.3], "rotate_deg": [0.0, 180.0, 0.0]}
    scene = _scene({"rows": 3, "cols": 4, "lf_camera": [160, 120], "projector": [80, 60], "exposure": 0.05},
                   interfaces=[{"name": "near"}, far],                      # (a full code stays below saturation)
                   synthetic=[_box("cube", (0.0, 0.0, -0.06), size=(0.04, 0.04, 0.04))], light=(0.3, 0.12, -0.1))
    near_model, far_model = nominal_interfaces(scene)
    world = SimInterfaces(scene, capture_spp=4)
    near, far_rig = world.rigs
    decoder = near_model.decoder(8, 8)
    dark = decoder(near.capture_lf().codes)
    white = np.full((*far_rig.info.projector_shape, 3), 255, np.uint8)
    far_rig.project(white)
    seen = decoder(near.capture_lf().codes) - dark
    # entries whose ray meets the far array well inside its extent (half a lenslet from its edges)
    d = seen.directions()                                              # (V, U, 3) unit, d_z > 0
    centres = near_model.array.centres
    hit = centres[:, None, None, :] + 0.3 * d[None, :, :, :2] / d[None, :, :, 2:3]
    x0, x1, y0, y1 = far_model.array.extent()
    margin = PITCH / 2
    inside = ((hit[..., 0] > x0 + margin) & (hit[..., 0] < x1 - margin) & (hit[..., 1] > y0 + margin)
              & (hit[..., 1] < y1 - margin) & seen.mask()[None])
    # and those a lenslet's width beyond it (an entry spans its aperture and an angular step, 2 cm there)
    outside = ~((hit[..., 0] > x0 - PITCH) & (hit[..., 0] < x1 + PITCH) & (hit[..., 1] > y0 - PITCH)
                & (hit[..., 1] < y1 + PITCH)) & seen.mask()[None]
    assert inside.sum() > 20 and outside.sum() > 20
    level = far_model.projector.max_radiance          # a full code, the nominal projector (no black level)
    # an entry averages its lenslet's aperture, whose rays may reach past the far lattice's jagged edge: most equal the
    # emitted radiance, none exceeds it
    assert np.median(seen.data[inside]) == pytest.approx(level, rel=0.01)
    assert np.mean(np.abs(seen.data[inside] - level) < 0.02 * level) > 0.6
    assert seen.data[inside].max() < 1.01 * level
    assert np.abs(seen.data[outside]).max() < 0.01 * level
    assert np.abs(dark.data).max() < 0.01 * level


def _rel(a, b) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def test_04_the_live_loop_through_both_interfaces_reaches_the_bounce_loops_fixed_point(variant):
    """The live loop through both arrays of the corner: frame 0 sees every projector black (the bounce loop's
    direct frame); each frame carries one more exchange, through both arrays at once, so after three frames each
    LF camera's capture and the real view equal the bounce loop's with two bounces. Frame 0 is far from that
    (negative control: the exchange adds about 5 % to each capture)."""
    from dataclasses import replace

    from lftransfer.transfer.live import LiveTransfer

    scene = _corner(lamp=True)
    models = nominal_interfaces(scene)
    world = SimInterfaces(scene, capture_spp=2)
    reference = run_interfaces(world.rigs, models, scene.synthetic_part(), SETTINGS)
    live = LiveTransfer(world.rigs[0], models[0], scene.synthetic_part(), replace(SETTINGS, bounces=1),
                        rigs=world.rigs, models=models)
    frames = [live.step(0.0) for _ in range(3)]
    assert [len(f.interfaces) for f in frames] == [2, 2, 2]
    assert not any(light.projected_lf.data.any() for light in frames[0].interfaces)
    # what each projector shows in frame k is what the synthetic side sent towards it in frame k - 1
    for before, after in zip(frames, frames[1:]):
        for a, b in zip(before.interfaces, after.interfaces):
            np.testing.assert_array_equal(b.projected_lf.data, a.synthetic_lf.data)
            assert b.projected_lf.data.any()
    np.testing.assert_allclose(frames[0].real_view, reference.real_view_direct, rtol=1e-5, atol=1e-7)
    for i in (0, 1):
        direct = reference.interfaces[i][0].real_lf.data
        every = sum(b.real_lf.data for b in reference.interfaces[i])
        gain = _rel(every, direct)                                         # measured 5.8 % and 5.2 %
        assert gain > 0.02
        assert _rel(frames[0].interfaces[i].captured_lf.data, direct) < 0.01 * gain      # measured 0.03 %, 0
        assert _rel(frames[2].interfaces[i].captured_lf.data, every) < 0.05 * gain       # measured 1.1 %, 1.5 %
        assert _rel(frames[0].interfaces[i].captured_lf.data, every) > 0.5 * gain
    view_gain = _rel(reference.real_view, reference.real_view_direct)
    assert view_gain > 0
    assert _rel(frames[2].real_view, reference.real_view) < 0.05 * view_gain            # measured 0.24 %
    # one interface's frame fields are the first's
    np.testing.assert_array_equal(frames[2].captured_lf.data, frames[2].interfaces[0].captured_lf.data)
