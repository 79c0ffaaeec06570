"""The environment recovered from a mirror ball the view camera photographs (lftransfer.real_depth.probe).

A known environment (a sky brighter towards +y and a small sun) lights a mirror ball 5 cm across, path traced by
Mitsuba from a view camera 40 cm away. What each test shows:
- test_01: the map's convention is Mitsuba's ``envmap`` (a texel lit alone lights the direction env_directions
  gives it).
- test_02: unwrapped, the recovered map puts the sun within 2 degrees of its true direction (1.2 measured: the
  texels are 2.8 degrees), carries the environment's power over the directions it measured to 2 % (1.5 % low:
  the sun's peak spread over the ball's edge pixels), and each measured sky texel to 1 % (median; 0.16 %
  measured); it covers over 90 % of the sphere of directions, all but the cone behind the ball. With the ball
  taken 5 mm off where it is (a badly calibrated position), the sun lands over 10 degrees away (23 measured; 1 mm:
  5 degrees): the negative control.
- test_03: through the simulated rig, on the built-in ``probe`` scene (its view at a quarter of the size): the
  pipeline photographs the ball on its mount and gets back the twin's room: its brightest spot within 0.5 degree
  (0.16 measured), the power over the directions it measured within 2.5 % (1.6 % low: the sun's peak spread over
  the ball's edge pixels), each quiet texel to 0.1 % (median), over 90 % of the sphere measured (92 %; the rest is
  the cone behind the ball and the rig itself). Negative control: the ball taken 5 mm off where its mount holds it
  moves the sun by more than 5 degrees (7.8 measured; 1 mm: 1.5).
- test_04: the map's unmeasured directions take the median of the measured ones at their elevation (a sun in the
  same row does not spread into them); the directions through the array from the ball are dropped.
- test_05: the negative control's point light (``direct_light = "point"``) stands at the map's brightest direction,
  1 m from the synthetic objects, and gives a surface facing it there the irradiance the whole map gives it.
"""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.backend import mitsuba
from lftransfer.real_depth.probe import EnvironmentMap, MirrorBall, env_directions, unwrap_mirror_ball
from lftransfer.render.camera import sensor_dict
from lftransfer.scenes.models import ViewConfig

SUN = np.array([0.5, 0.6, 0.62]) / np.linalg.norm([0.5, 0.6, 0.62])


def _environment(width: int = 128, height: int = 64) -> np.ndarray:
    d = env_directions(width, height)
    sky = 0.2 + 0.8 * np.clip(d[..., 1], 0, 1)                         # brighter towards +y
    sun = 400.0 * np.exp(-(1 - d @ SUN) / (1 - np.cos(np.radians(2.5))))
    rgb = np.stack([sky * 0.6 + sun, sky * 0.8 + sun, sky + sun], -1)
    return rgb.astype(np.float32)


def test_01_the_convention_is_mitsubas():
    mi = mitsuba()
    import drjit as dr

    img = np.zeros((16, 32, 3), np.float32)
    img[5, 21] = 1.0
    em = mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(img)})
    d = env_directions(32, 16)
    si = dr.zeros(mi.SurfaceInteraction3f, 16 * 32)
    flat = d.reshape(-1, 3)
    si.wi = mi.Vector3f(-flat[:, 0], -flat[:, 1], -flat[:, 2])
    value = np.array(em.eval(si))
    value = (value if value.shape[-1] == 3 else value.T)[:, 0].reshape(16, 32)
    assert np.unravel_index(np.argmax(value), value.shape) == (5, 21)


@pytest.fixture(scope="module")
def ball_photo():
    mi = mitsuba()
    view = ViewConfig(resolution=(160, 120), origin=[0.0, 0.05, 0.4], target=[0.0, 0.0, 0.0], up=[0.0, 1.0, 0.0],
                      fov_deg=12.0)
    ball = MirrorBall(centre=(0.0, 0.0, 0.0), radius=0.025)
    w, h = view.resolution
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 3},
        "sensor": sensor_dict(view.origin, view.target, view.up, view.fov_deg, w, h, spp=64),
        "env": {"type": "envmap", "bitmap": mi.Bitmap(_environment())},
        "ball": {"type": "sphere", "center": list(ball.centre), "radius": ball.radius,
                 "bsdf": {"type": "conductor", "material": "none"}}})
    image = np.array(mi.render(scene, spp=64), np.float32)[..., :3]
    return image, view, ball


def _sun_error_deg(env: EnvironmentMap) -> float:
    return float(np.degrees(np.arccos(np.clip(env.brightest_direction() @ SUN, -1, 1))))


def test_02_the_ball_gives_back_the_environment(ball_photo):
    image, view, ball = ball_photo
    env = unwrap_mirror_ball(image, view, ball)
    truth = EnvironmentMap(_environment(), env.valid)
    assert env.valid.mean() > 0.9                                     # all but the cone behind the ball
    behind = env_directions(128, 64) @ (np.array(view.origin) / np.linalg.norm(view.origin))
    assert not env.valid[behind < -0.95].any()
    assert _sun_error_deg(env) < 2.0, _sun_error_deg(env)
    assert np.allclose(env.power(), truth.power(), rtol=0.02), (env.power(), truth.power())
    sky = env.valid & (env_directions(128, 64) @ SUN < np.cos(np.radians(15)))
    rel = np.abs(env.radiance[sky] - truth.radiance[sky]) / truth.radiance[sky]
    assert np.median(rel) < 0.01, np.median(rel)
    # negative control: the ball 5 mm off where the unwrap takes it to be
    off = MirrorBall(centre=(0.005, 0.0, 0.0), radius=ball.radius)
    assert _sun_error_deg(unwrap_mirror_ball(image, view, off)) > 10.0


@pytest.fixture(scope="module")
def probe_scene():
    from lftransfer.scenes import builtin_scene, load_scene, with_overrides

    return with_overrides(load_scene(builtin_scene("probe")), view={"resolution": [256, 192]})


def test_03_the_simulated_rig_shows_its_room(variant, probe_scene):
    from lftransfer.real_depth.probe import photograph_probe
    from lftransfer.settings import resolve_settings
    from lftransfer.sim.metrics import probe_errors
    from lftransfer.sim.rig import SimRig
    from lftransfer.transfer.synthetic_side import SyntheticSide

    rig = SimRig(probe_scene)
    side = SyntheticSide(rig.truth, probe_scene.synthetic_part(), resolve_settings(probe_scene).transfer)
    truth = probe_scene.environment.radiance_map()
    w2a = rig.truth.world_to_array()
    probe = side.measure_probe(rig)
    errors = probe_errors(probe, truth, w2a)
    assert errors["brightest_direction_error_deg"] < 0.5, errors
    assert abs(errors["power_ratio"] - 1) < 0.025, errors
    assert errors["texel_rel_error_median"] < 0.001, errors
    assert errors["measured_share"] > 0.9, errors
    assert probe.photo.shape == (192, 256, 3) and probe.radiance.shape == (64, 128, 3)
    # negative control: the ball stands where its mount holds it, the unwrap takes it 5 mm away
    p = side.posed().probe
    off = MirrorBall((p.ball_centre[0] + 0.005, p.ball_centre[1], p.ball_centre[2]), p.ball_radius)
    wrong = photograph_probe(rig, probe_scene.probe.ball_centre, off, side.posed().view, rig.truth.array.extent())
    assert probe_errors(wrong, truth, w2a)["brightest_direction_error_deg"] > 5.0


def test_04_the_unmeasured_directions_are_filled():
    from lftransfer.real_depth.probe import fill_environment, through_array

    h, w = 16, 32
    rad = np.zeros((h, w, 3), np.float32)
    rad[:] = np.linspace(0.1, 1.6, h, dtype=np.float32)[:, None, None]      # changes with elevation only
    rad[6, 3] = 500.0                                                       # a sun
    valid = np.ones((h, w), bool)
    valid[4:9, 10:20] = False
    filled = fill_environment(EnvironmentMap(np.where(valid[..., None], rad, 0), valid))
    assert np.allclose(filled[valid], rad[valid])
    assert np.allclose(filled[4:9, 10:20], rad[4:9, 10:20], rtol=1e-6)      # the sun's row keeps its sky
    # from in front of a 30 x 22 cm array, straight back (-z) goes through it; straight up does not
    hit = through_array((0.0, 0.0, 0.08), 64, 32, (-0.15, 0.15, -0.11, 0.11))
    d = env_directions(64, 32)
    assert hit[d[..., 2] < -0.99].all() and not hit[d[..., 1] > 0.9].any() and not hit[d[..., 2] > 0].any()


def test_05_the_point_light_that_stands_in_for_the_probe(variant, probe_scene):
    from lftransfer.render.lights import EnvironmentLight
    from lftransfer.transfer.synthetic_side import PROBE_POINT_DISTANCE_M, probe_point_light

    room = probe_scene.environment.radiance_map()
    posed = probe_scene.synthetic_part()
    light = probe_point_light(room, posed)
    lo, hi = posed.synthetic[0].bounds()
    centre = (np.asarray(lo) + np.asarray(hi)) / 2
    offset = light.position - centre
    assert np.linalg.norm(offset) == pytest.approx(PROBE_POINT_DISTANCE_M)
    sun = np.asarray(probe_scene.environment.sun_direction) / np.linalg.norm(probe_scene.environment.sun_direction)
    assert np.degrees(np.arccos(offset @ sun)) < 1.0
    expected = EnvironmentLight(room).irradiance_towards(offset)
    assert light.intensity / PROBE_POINT_DISTANCE_M ** 2 == pytest.approx(expected)
