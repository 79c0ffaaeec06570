"""Global pose: the view camera model, the fringe light fields and their decoding, the pose solve and its
application."""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.optics.geometry import backproject, view_camera
from lftransfer.calibration.pose import (FRINGE_PERIOD_M, ArrayPose, apply_pose, board_pattern, decode_fringes,
                                         fringe_lightfields, solve_array_pose)
from lftransfer.rig.model import nominal_rig
from lftransfer.scenes import builtin_scene, load_scene
from lftransfer.scenes.frame import rotation_xy


@pytest.fixture(scope="module")
def scene():
    return load_scene(builtin_scene("fig4"))


def test_01_view_camera_matches_mitsuba(variant, scene):
    """A point on Mitsuba's ray through a pixel's centre projects to that pixel with our pinhole model."""
    from lftransfer.backend import mitsuba
    from lftransfer.render.camera import sensor_dict

    mi = mitsuba()
    v = scene.view
    w, h = v.resolution
    sensor = mi.load_dict(sensor_dict(v.origin, v.target, v.up, v.fov_deg, w, h))
    px = np.array([[10, 20], [w // 2, h // 3], [w - 7, h - 5]], np.float64)
    ray, _ = sensor.sample_ray(mi.Float(0.0), mi.Float(0.5),
                               mi.Point2f(((px[:, 0] + 0.5) / w).astype(np.float32),
                                          ((px[:, 1] + 0.5) / h).astype(np.float32)), mi.Point2f(0.5, 0.5))
    d = np.array(ray.d).T
    X = np.asarray(v.origin) + 0.7 * d
    K, R, t = view_camera(v)
    p = (X @ R.T + t) @ K.T
    np.testing.assert_allclose(p[:, :2] / p[:, 2:3], px, atol=1e-3)
    # and back: pixels -> points on a plane -> the same pixels
    normal = np.array([0.3, 0.1, -1.0]) / np.linalg.norm([0.3, 0.1, -1.0])
    Y = backproject(v, px, np.array([0.0, 0.0, 0.1]), normal)
    q = (Y @ R.T + t) @ K.T
    np.testing.assert_allclose(q[:, :2] / q[:, 2:3], px, atol=1e-6)
    np.testing.assert_allclose((Y - [0.0, 0.0, 0.1]) @ normal, 0, atol=1e-12)


def test_02_fringe_lightfields_draw_the_board_coordinates(scene):
    """With one ray per cell, each sample of shift j carries (1 + cos(2 pi s / T + 2 pi j / 4)) / 2 of the peak
    radiance, with s the board coordinate where its central ray meets the plane; samples that miss the lit
    rectangle are dark; with four shifts the mean over shifts is half the peak wherever the rays hit."""
    array = nominal_rig(scene.rig).array
    board = board_pattern(scene.view, 0.08)
    extent = (0.15, 0.12)
    fringes = fringe_lightfields(array, 16, 16, board, extent, 2.0, supersample=1)
    assert len(fringes) == 8
    d = fringes[0].directions()
    c = array.centres3d[:, None, None, :]
    t = ((board.centre - c) @ board.normal) / (d @ board.normal)
    rel = c + t[..., None] * d[None] - board.centre
    a, b = rel @ board.ex, rel @ board.ey
    hit = (t > 0) & (np.abs(a) < extent[0] / 2) & (np.abs(b) < extent[1] / 2) & fringes[0].mask()[None]
    assert hit.sum() > 1000 and (~hit).sum() > 1000
    for axis, coord in enumerate((a, b)):
        for j in range(4):
            want = np.where(hit, 1.0 + np.cos(2 * np.pi * coord / FRINGE_PERIOD_M + np.pi * j / 2), 0.0)
            np.testing.assert_allclose(fringes[4 * axis + j].data[..., 1], want, atol=1e-5)
    mean = np.mean([f.data[..., 0] for f in fringes[:4]], axis=0)
    np.testing.assert_allclose(mean, np.where(hit, 1.0, 0.0), atol=1e-5)


def test_03_fringes_decode_to_board_coordinates(scene):
    """Photographs of blurred, unevenly lit fringes on a board give every pixel the board coordinates drawn there,
    with the period's index from a prediction a few millimetres off; a prediction off by more than half a period
    picks the wrong period (negative control: the unwrapping does rely on it)."""
    view = scene.view
    w, h = view.resolution
    board = board_pattern(view, 0.1)
    extent = (0.2, 0.16)
    ys, xs = np.mgrid[0:h, 0:w]
    px = np.stack([xs.ravel(), ys.ravel()], 1).astype(np.float64)
    X = backproject(view, px, board.centre, board.normal) - board.centre
    a, b = (X @ board.ex).reshape(h, w), (X @ board.ey).reshape(h, w)
    albedo = 0.3 + 0.2 * (np.floor(a / 0.022) % 2) + 0.1 * b          # a printed chart, light fall-off
    shots = []
    for coord in (a, b):
        for j in range(4):
            wave = 0.5 + 0.5 * 0.6 * np.cos(2 * np.pi * coord / FRINGE_PERIOD_M + np.pi * j / 2)   # 60 % contrast
            shots.append(np.repeat((albedo * wave)[..., None], 3, axis=2))

    def shifted(offset):
        return lambda P: P + offset

    dec = decode_fringes(shots, board, extent, view, shifted(np.array([0.004, -0.003, 0.002])))
    inside = (np.abs(a) < extent[0] / 2 - 0.0254) & (np.abs(b) < extent[1] / 2 - 0.0254)
    assert dec.valid.sum() > 0.95 * inside.sum() and not np.any(dec.valid & ~inside)
    np.testing.assert_allclose(dec.coords[dec.valid][:, 0], a[dec.valid], atol=1e-9)
    np.testing.assert_allclose(dec.coords[dec.valid][:, 1], b[dec.valid], atol=1e-9)
    np.testing.assert_allclose(dec.contrast[dec.valid], 0.6, atol=1e-6)
    wrong = decode_fringes(shots, board, extent, view, shifted(0.04 * board.ex))
    err = np.abs(wrong.coords[..., 0] - a)[wrong.valid & inside]
    assert np.median(err) == pytest.approx(FRINGE_PERIOD_M, abs=1e-6)


def test_04_pose_recovered_from_exact_correspondences(scene):
    """Model-frame corners carried by a known pose are mapped back to that pose (tilt, rotation, offset, scale)."""
    board = board_pattern(scene.view, 0.08)
    truth = ArrayPose(tilt=(np.radians(0.4), np.radians(-0.3)), rotation=np.radians(1.7), offset=(0.0021, -0.0013),
                      scale=1.008)
    corners = board.corners()
    fit = solve_array_pose(corners, truth.model_to_world(corners))
    assert fit.residual_mm < 1e-6
    np.testing.assert_allclose(fit.tilt, truth.tilt, atol=1e-9)
    np.testing.assert_allclose([fit.rotation, fit.scale, *fit.offset], [truth.rotation, truth.scale, *truth.offset],
                               atol=1e-9)
    assert ArrayPose.from_json(fit.to_json()).to_json() == fit.to_json()


def test_05_apply_pose_keeps_every_pixels_ray(scene):
    """A device pixel sees the same world ray whether its model-frame ray is carried by the pose, or the posed
    model is asked directly."""
    model = nominal_rig(scene.rig)
    pose = ArrayPose(tilt=(0.004, -0.006), rotation=0.03, offset=(0.002, -0.001), scale=1.006)
    posed = apply_pose(model, pose)
    rng = np.random.default_rng(0)
    dev = model.camera.device
    px = np.stack([rng.uniform(0, dev.width - 1, 3000), rng.uniform(0, dev.height - 1, 3000)], 1)
    k0, d0 = dev.pixel_to_ray(model.array, px)
    k1, d1 = posed.camera.device.pixel_to_ray(posed.array, px)
    ok = k0 >= 0
    assert np.array_equal(k0, k1) and ok.sum() > 1000
    origin0 = pose.model_to_world(model.array.centres3d[k0[ok]])
    c, s = np.cos(pose.rotation), np.sin(pose.rotation)
    world_dir0 = d0[ok] @ (rotation_xy(pose.tilt) @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])).T
    origin1 = posed.array.centres3d[k1[ok]] @ rotation_xy(posed.tilt).T
    world_dir1 = d1[ok] @ rotation_xy(posed.tilt).T
    np.testing.assert_allclose(origin1, origin0, atol=1e-12)
    np.testing.assert_allclose(world_dir1, world_dir0, atol=1e-9)


def test_06_no_board_in_view_is_a_clear_error(scene):
    """A rig whose board photographs are black: the pose step says what it could not find."""
    from lftransfer.calibration.pose import PoseError, calibrate_pose

    from tests.fakes import DarkRig

    rig = DarkRig(lf_camera=scene.rig.lf_camera, projector=scene.rig.projector, view=scene.view.resolution)
    with pytest.raises(PoseError, match="chessboard was not found"):
        calibrate_pose(rig, nominal_rig(scene.rig), scene)
    assert rig.setups[-1].chart is not None          # the operator was asked for the board with the chart


def test_07_corners_land_where_their_rays_meet_the_board(scene):
    """On the drawing plane a corner lands where it was drawn; on a board moved along the axis its rays' centroid
    moves along the axis too (the lenslets that draw a central corner lie symmetrically around it)."""
    from lftransfer.calibration.pose import corner_landing

    array = nominal_rig(scene.rig).array
    board = board_pattern(scene.view, 0.08, (5, 4), 0.028)
    drawn = board.corners()
    same = corner_landing(array, drawn, board.centre, board.normal)
    np.testing.assert_allclose(same, drawn, atol=1e-12)
    centre = np.array([[0.0, 0.0, 0.08]])
    moved = corner_landing(array, centre, np.array([0.0, 0.0, 0.083]), np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(moved, [[0.0, 0.0, 0.083]], atol=2e-4)


def test_08_pose_from_misplaced_boards(scene):
    """Exact corner landings on two boards held off the asked-for planes recover a hidden pose, where fitting the
    corners as drawn does not (negative control)."""
    from lftransfer.calibration.pose import corner_landing

    array = nominal_rig(scene.rig).array
    truth = ArrayPose(tilt=(np.radians(0.3), np.radians(-0.4)), rotation=np.radians(1.5), offset=(0.002, -0.001),
                      scale=1.006)
    drawn, world, planes = [], [], []
    for depth, shift, turn in ((0.07, 0.003, 1.0), (0.12, -0.002, -0.8)):
        board = board_pattern(scene.view, depth, (5, 4), 0.028)
        c = np.cos(np.radians(turn))
        normal = truth.model_to_world(board.normal[None])[0] - truth.model_to_world(np.zeros((1, 3)))[0]
        normal = normal / np.linalg.norm(normal)
        normal = c * normal + np.sqrt(1 - c * c) * np.cross(normal, [0.0, 1.0, 0.0])
        point = truth.model_to_world(board.centre[None])[0] + shift * normal
        land = corner_landing(array, board.corners(), truth.world_to_model(point[None])[0],
                              truth.direction_to_model(normal[None])[0])
        drawn.append(board.corners())
        world.append(truth.model_to_world(land))
        planes.append((point, normal, len(land)))
    drawn, world = np.concatenate(drawn), np.concatenate(world)

    def landing(candidate):
        out, i = [], 0
        for point, normal, n in planes:
            out.append(corner_landing(array, drawn[i:i + n], candidate.world_to_model(point[None])[0],
                                      candidate.direction_to_model(normal[None])[0]))
            i += n
        return np.concatenate(out)

    naive = solve_array_pose(drawn, world)
    pose = solve_array_pose(drawn, world, landing=landing, start=naive)
    assert abs(pose.scale - truth.scale) < 1e-5 and abs(pose.rotation - truth.rotation) < 1e-5
    np.testing.assert_allclose(pose.tilt, truth.tilt, atol=1e-5)
    np.testing.assert_allclose(pose.offset, truth.offset, atol=1e-6)
    assert pose.residual_mm < 1e-3
    assert naive.residual_mm > 0.3 or abs(naive.scale - truth.scale) > 1e-3
