"""Step (d) of :mod:`lftransfer.calibration.radiometric`: the projector's absolute brightness from a board seen by
the view camera, against our own render of it."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from lftransfer.calibration.chart import PoseError, chart_pose
from lftransfer.calibration.radiometric.common import (BOARD_ALBEDO, BOARD_CHART, BOARD_DISTANCES, BOARD_SIZE, Progress,
                                                      RadiometryError)
from lftransfer.calibration.radiometric.projector import _ProjectorFit
from lftransfer.lightfield import ResponseCurve
from lftransfer.optics.geometry import project
from lftransfer.render.shapes import board_shapes, lens_array_absorber
from lftransfer.rig.base import Rig
from lftransfer.rig.requests import SCREEN_TRANSMISSION, Board, ViewCapture


def _board_pose(scene, model, translucent: bool = False, walls=None):
    """Where the board is asked for: centre, normal (rig frame, the best guess of the model's frame before the
    pose step), the view camera in the model's array frame and the board centre's view pixel.

    The centre lies on the array's axis at the first of :data:`BOARD_DISTANCES` whose image falls well inside
    the view (15 % from every border); the normal is half-way between -z (towards the array, which lights it)
    and the direction to the view camera, or, for a ``translucent`` screen seen from behind, half-way between -z
    and the direction away from it (:func:`~lftransfer.calibration.pose.board_pattern`, clear of ``walls``: the
    other interfaces' planes).
    """
    from lftransfer.calibration.pose import board_pattern
    from lftransfer.scenes.frame import scene_in_frame

    view = scene_in_frame(scene, model.world_to_array()).view
    vw, vh = view.resolution
    for z in BOARD_DISTANCES:
        board = board_pattern(scene.view, z, translucent=translucent, extent=BOARD_SIZE, walls=walls)
        centre, normal = tuple(board.centre.tolist()), board.normal
        px = project(view, board.centre[None])[0]
        if 0.15 * vw <= px[0] <= 0.85 * vw and 0.15 * vh <= px[1] <= 0.85 * vh:
            return centre, normal, view, tuple(int(round(v)) for v in px)
    raise RadiometryError(f"brightness: no board position {BOARD_DISTANCES} m in front of the array centre "
                          "is seen well by the view camera")


def _window_rays(sensor, width: int, height: int, xs: np.ndarray, ys: np.ndarray, spp: int, seed: int):
    """Primary rays (jittered, ``spp`` per pixel, pixel-major) through the given view camera pixels."""
    from lftransfer.backend import mitsuba

    mi = mitsuba()
    rng = np.random.default_rng(seed)
    n = len(xs)
    px = (xs[:, None] + rng.random((n, spp))) / width
    py = (ys[:, None] + rng.random((n, spp))) / height
    ray, _ = sensor.sample_ray(mi.Float(0.0), mi.Float(0.5),
                               mi.Point2f(px.ravel().astype(np.float32), py.ravel().astype(np.float32)),
                               mi.Point2f(0.5, 0.5))
    centre = np.array(sensor.world_transform().translation(), dtype=np.float32).ravel()[:3]
    d = np.ascontiguousarray(np.array(ray.d, dtype=np.float32).T)
    return np.ascontiguousarray(np.broadcast_to(centre, (n * spp, 3))), d


def _held_board(image: np.ndarray, view, asked_normal) -> np.ndarray:
    """(4, 4) ``to_world`` of the board rectangle where the view camera sees it stand (its printed chart's pose),
    facing the side it was asked to face."""
    try:
        m, _ = chart_pose(image, BOARD_CHART, view)
    except PoseError as exc:
        raise RadiometryError(f"brightness: {exc}") from None
    if m[:3, 2] @ np.asarray(asked_normal, np.float64) < 0:       # keep a right-handed frame facing the array
        m[:3, 1:3] *= -1
    m[:3, 0] *= BOARD_SIZE[0] / 2
    m[:3, 1] *= BOARD_SIZE[1] / 2
    return m


def _predict_board(model, scene, projector, image: np.ndarray, to_world: np.ndarray,
                   pixels: tuple[np.ndarray, np.ndarray], *, angular_samples: int, spp: int, aperture_samples: int,
                   seed: int = 0, translucent: bool = False):
    """Our own render of the board (``to_world``: its rectangle, printed chart included; a ``translucent`` screen
    with its datasheet's transmission, seen from behind) at view pixels, lit by ``projector`` showing ``image``."""
    from lftransfer.backend import mitsuba
    from lftransfer.lightfield import LightFieldEncoder
    from lftransfer.render.camera import sensor_dict
    from lftransfer.render.lights import LightFieldLight
    from lftransfer.render.renderer import HalfSpaceRenderer
    from lftransfer.scenes.frame import scene_in_frame

    mi = mitsuba()
    array = model.array
    view = scene_in_frame(scene, model.world_to_array()).view
    shapes = board_shapes(to_world, BOARD_ALBEDO, BOARD_CHART, SCREEN_TRANSMISSION if translucent else 0.0)
    renderer = HalfSpaceRenderer([], extra_shapes={**shapes, "lens_array_absorber": lens_array_absorber(array)},
                                 max_depth=1)
    encoder = LightFieldEncoder(array, projector, angular_samples, angular_samples)
    lf = encoder.codec.image_to_lightfield(encoder.emitted(image))
    light = LightFieldLight(lf, side="real", model="area", aperture_samples=aperture_samples, seed=seed + 3)
    w, h = view.resolution
    sensor = mi.load_dict(sensor_dict(view.origin, view.target, view.up, view.fov_deg, w, h))
    xs, ys = pixels
    o, d = _window_rays(sensor, w, h, xs.astype(np.float64), ys.astype(np.float64), spp, seed)
    radiance, hit, _ = renderer.render_rays(o, d, [light], seed=seed)
    return radiance.reshape(len(xs), spp, 3).mean(1), hit.reshape(len(xs), spp).all(1), view


@dataclass
class _BoardMeasurement:
    """Step (d): the projector's absolute brightness from a board seen by the view camera.

    Attributes:
        max_radiance: measured over predicted radiance (at ``max_radiance = 1``), all channels pooled.
        per_channel: ``(3,)`` the same ratio per channel.
        measured_mean: ``(3,)`` mean measured radiance of the pixels used.
        pixels: view pixels used (the board hit by every ray of our render, not dark).
        held: ``(4, 4)`` ``to_world`` of the board where it really stood (its printed chart's pose).
        centre_pixel: ``(x, y)`` view pixel of the held board's centre.
        translucent: whether the board was a translucent screen seen from behind (the opaque board's chart was not
            found: a view camera that sees its back sees it too obliquely).
    """

    max_radiance: float
    per_channel: np.ndarray
    measured_mean: np.ndarray
    pixels: int
    held: np.ndarray
    centre_pixel: tuple[int, int]
    translucent: bool = False


def _photograph_board(rig: Rig, scene, asked, white: np.ndarray, board_spp: int | None, translucent: bool):
    """The board (a ``translucent`` screen or not) asked for where ``asked`` (:func:`_board_pose`) says, lit by the
    projector's ``white`` image and photographed: (the view image, where the board really stands from its chart)."""
    centre, normal, _, _ = asked
    rig.setup(Board(centre=centre, normal=tuple(normal), size=BOARD_SIZE, albedo=BOARD_ALBEDO, chart=BOARD_CHART,
                    translucent=translucent))
    rig.project(white)
    measured = rig.capture_view(ViewCapture(quality=board_spp)).radiance
    return measured, _held_board(measured, scene.view, normal)         # held by hand: from its chart


def _measure_brightness(rig: Rig, model, scene, projector_fit: _ProjectorFit, white: np.ndarray, *,
                        board_spp: int | None, predict_spp: int, angular_samples: int, seed: int,
                        say: Progress, walls=None) -> _BoardMeasurement:
    """Step (d, i): the board lit by the full-code projector image, measured and predicted by our own render.

    The view pixels around the held board's centre (a square of half-width 4 % of the view's width, halved up
    to 3 times until our render's rays all hit the board) are rendered lit by the calibrated projector model at
    ``max_radiance = 1``.

    Returns:
        The ratio of measured to predicted radiance and the board measurement.

    Raises:
        RadiometryError: no board position is seen well, its chart is not found, its centre projects outside
            the view, or our render of it is dark.
    """
    say("projector brightness: board in front of the array (view camera)")
    asked = _board_pose(scene, model)        # centre, normal, the view camera in the model's array frame, pixel
    translucent = False
    try:
        measured, held = _photograph_board(rig, scene, asked, white, board_spp, translucent)
    except RadiometryError:
        from lftransfer.calibration.pose import sees_lit_side

        if sees_lit_side(scene.view, asked[0][2]):
            raise
        # a view camera that sees the board's back may see its chart too obliquely: a screen, seen from behind
        translucent = True
        asked = _board_pose(scene, model, translucent, walls)
        measured, held = _photograph_board(rig, scene, asked, white, board_spp, translucent)
    view = asked[2]
    cx, cy = (int(round(v)) for v in project(view, held[:3, 3][None])[0])
    projector = replace(model.projector, response=ResponseCurve(tuple(projector_fit.gamma)), max_radiance=1.0,
                        cross_talk=projector_fit.cross_talk, black_level=tuple(projector_fit.black_level.tolist()))
    vw, vh = view.resolution
    half = max(3, int(round(0.04 * vw)))
    say("projector brightness: our own render of the board")
    for _ in range(4):
        ys, xs = np.mgrid[max(cy - half, 0):min(cy + half + 1, vh), max(cx - half, 0):min(cx + half + 1, vw)]
        xs, ys = xs.ravel(), ys.ravel()
        if len(xs) == 0:
            raise RadiometryError(f"brightness: the board centre projects outside the view camera ({cx}, {cy})")
        predicted, hit, _ = _predict_board(model, scene, projector, white, held, (xs, ys),
                                           angular_samples=angular_samples, spp=predict_spp,
                                           aperture_samples=8, seed=seed, translucent=translucent)
        if hit.all() or half <= 3:
            break
        half = max(3, half // 2)
    use = hit & (predicted.sum(1) > 0)
    if use.sum() < 9:
        raise RadiometryError("brightness: our render of the board is dark around its centre")
    meas = measured[ys[use], xs[use]].astype(np.float64)
    pred = predicted[use].astype(np.float64)
    return _BoardMeasurement(max_radiance=float(meas.sum() / pred.sum()), per_channel=meas.sum(0) / pred.sum(0),
                             measured_mean=meas.mean(0), pixels=int(use.sum()), held=held, centre_pixel=(cx, cy),
                             translucent=translucent)
