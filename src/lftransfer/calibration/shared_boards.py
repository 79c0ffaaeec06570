"""Boards that two light field interfaces light at once: their poses tied together (docs/interfaces.md, "Calibration
into one world frame").

Each interface's own pose step (:func:`~lftransfer.calibration.pose.calibrate_pose`) measures its array in the world
from boards only it lights; the two arrays' errors then add up in the light that crosses from one to the other. Here
a board stands where interface 0 and interface i both light it (at the same distance from both arrays' planes, the
two arrays' rays meeting it from either side), and each array draws its fringes on it in turn while the view camera
photographs it. Both arrays are solved from the same boards, whose planes are measured once: an error of that
measurement (the printed chart's pose, the operator's hand) moves both fits alike, so the arrays' pose relative to
each other, A_0^-1 A_i, is nearly free of it. Interface i's pose becomes interface 0's own pose carried by that
relative pose: the arrays are tied through what both drew, not only through the view camera's frame.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from lftransfer.calibration.pose import (CHART, ArrayPose, PoseError, _drawn_on, _sample_valid, _solve_boards,
                                         apply_pose, board_plane, solve_array_pose, unapply_pose)
from lftransfer.lightfield import LightField
from lftransfer.lightfield.fringes import FRINGE_SHIFTS, BoardPattern, decode_fringes, fringe_lightfields
from lftransfer.optics.geometry import backproject, plane_axes, rigid_points, rigid_vectors
from lftransfer.rig.base import Rig
from lftransfer.rig.requests import Board, RealScene, ViewCapture

__all__ = ["SHARED_DEPTHS", "count_shared_steps", "shared_board", "tie_interfaces"]

SHARED_DEPTHS = (0.09, 0.13)   # metres: each shared board's centre from both arrays' planes (two, for parallax)
SHARED_SPP = 16                # view camera quality of the shared boards' photographs (as the pose step's)


def count_shared_steps(scene) -> int:
    """Progress messages of :func:`tie_interfaces` for a scene of several interfaces."""
    return (len(scene.interfaces) - 1) * len(SHARED_DEPTHS) * (1 + 2 * 2 * FRINGE_SHIFTS)


def shared_board(scene, a: int, b: int, depth: float) -> tuple[BoardPattern, bool]:
    """Where a board that interfaces ``a`` and ``b`` both light stands (world frame), and whether it is a translucent
    screen (the view camera on its far side from the arrays).

    Its centre is ``depth`` in front of both arrays' planes, the point of that line nearest the middle of the two
    arrays' centres; it faces halfway between the two arrays and is turned halfway towards the view camera (an
    opaque board), or away from it (a screen the camera sees from behind), as
    :func:`~lftransfer.calibration.pose.board_pattern` turns one interface's boards."""
    to_world = [scene.interfaces[k].to_world() for k in (a, b)]
    centres = np.array([m[:3, 3] for m in to_world])
    normals = np.array([m[:3, 2] for m in to_world])               # each array's real side, world frame
    middle = centres.mean(axis=0)
    rhs = depth + np.einsum("ij,ij->i", normals, centres) - normals @ middle
    centre = middle + np.linalg.pinv(normals) @ rhs
    towards = -(normals[0] + normals[1])
    towards /= np.linalg.norm(towards)                              # from the board towards both arrays
    to_cam = np.asarray(scene.view.origin, np.float64) - centre
    to_cam /= np.linalg.norm(to_cam)
    screen = bool(to_cam @ towards < 0)
    ex, ey, normal = plane_axes(towards - to_cam if screen else towards + to_cam)
    return BoardPattern(centre, normal, ex, ey), screen


@dataclass
class _Array:
    """One interface as the shared boards see it: its rig, its model before the pose, its own pose and its frame."""

    rig: Rig
    model: object                  # RigModel in the model frame (lenslets, mapping, radiometry; no pose)
    pose: ArrayPose                # its own pose step's: model frame -> interface frame
    to_world: np.ndarray           # (4, 4) interface frame -> world

    def model_to_world(self, X: np.ndarray) -> np.ndarray:
        return rigid_points(self.to_world, self.pose.model_to_world(X))

    def world_to_model(self, X: np.ndarray) -> np.ndarray:
        return self.pose.world_to_model(rigid_points(np.linalg.inv(self.to_world), X))

    def direction_to_model(self, v: np.ndarray) -> np.ndarray:
        return self.pose.direction_to_model(rigid_vectors(self.to_world, v, back=True))


def tie_interfaces(rigs: list[Rig], scene, calibrations: list, *, chart=CHART,
                   progress: Callable[[str], None] | None = None) -> tuple[list, list[dict]]:
    """Tie every interface's pose to the first's through boards both light (module docstring).

    Args:
        rigs: one rig per interface, in the scene's order.
        scene: the synthetic part of the scene (world frame: its ``[[interface]]`` tables and view camera).
        calibrations: each interface's own calibration (:func:`~lftransfer.calibration.rig.calibrate_rig` in its
            frame, not yet placed).
        chart: the chessboard printed on the boards.
        progress: called with a message per capture.

    Returns:
        (the calibrations, every one after the first with its pose carried from the first's by the shared boards;
        per interface after the first, what the boards measured: its own pose, the tied one and how far apart).
    """
    say = progress or (lambda _msg: None)
    arrays = [_Array(rig, unapply_pose(cal.model, cal.pose), cal.pose, scene.interfaces[k].to_world())
              for k, (rig, cal) in enumerate(zip(rigs, calibrations))]
    out, diagnostics = list(calibrations), []
    for i in range(1, len(rigs)):
        name = scene.interfaces[i].name
        boards = {0: [], i: []}
        for depth in SHARED_DEPTHS:
            for k, seen in _photograph_shared(arrays, scene, i, depth, chart,
                                              lambda msg, d=depth: say(f"{name}: shared board at {100 * d:.0f} cm "
                                                                       f"{msg}")).items():
                boards[k].append(seen)
        shared = {k: _solve_boards(arrays[k].model.array, boards[k], _in_frame(scene.view, arrays[k]),
                                   start=arrays[k].pose) for k in (0, i)}
        tied = _carried(arrays[0], arrays[i], shared[0], shared[i])
        cal = calibrations[i]
        out[i] = replace(cal, model=apply_pose(arrays[i].model, tied), pose=tied)
        diagnostics.append({"interface": name, "own": cal.pose.to_json(), "tied": tied.to_json(),
                            "shared_first": shared[0].to_json(), "shared": shared[i].to_json(),
                            "moved_mm": _moved_mm(arrays[i], cal.pose, tied)})
    for rig in rigs:
        rig.project(rig.info.black())
        rig.setup(RealScene())
    return out, diagnostics


def _in_frame(view, array: _Array):
    """The view camera in an interface's frame (for the fit's reprojection, diagnostics only)."""
    inv = np.linalg.inv(array.to_world)
    return view.model_copy(update={"origin": rigid_points(inv, np.asarray([view.origin], float))[0].tolist(),
                                   "target": rigid_points(inv, np.asarray([view.target], float))[0].tolist(),
                                   "up": rigid_vectors(inv, np.asarray([view.up], float))[0].tolist()})


def _photograph_shared(arrays: list[_Array], scene, i: int, depth: float, chart,
                       say: Callable[[str], None]) -> dict[int, dict]:
    """One shared board of interfaces 0 and ``i``: asked for through the first's rig, its plane found from the chart
    under both arrays' flood, then each array's fringes drawn on it in turn (the other dark) and decoded. Returns
    per interface the board's observations in its frame (:func:`~lftransfer.calibration.pose._solve_boards`)."""
    n = scene.rig.angular_samples
    size = ((chart[0] + 2) * chart[2], (chart[1] + 2) * chart[2])
    world_board, screen = shared_board(scene, 0, i, depth)
    first, pair = arrays[0], (0, i)
    asked = {k: _board_in(world_board, arrays[k]) for k in pair}
    first.rig.setup(Board(centre=tuple(float(v) for v in rigid_points(np.linalg.inv(first.to_world),
                                                                         world_board.centre[None])[0]),
                          normal=tuple(float(v) for v in rigid_vectors(first.to_world, world_board.normal[None],
                                                                       back=True)[0]),
                          size=size, chart=tuple(chart), translucent=screen))
    levels = {k: 0.9 * arrays[k].model.projector.max_radiance for k in pair}
    encoders = {k: arrays[k].model.encoder(n, n) for k in pair}
    say("photographed with both arrays' flood light fields")
    for k in pair:
        flood = LightField.zeros(arrays[k].model.array, n, n)
        flood.data[...] = 0.5 * levels[k]
        arrays[k].rig.project(encoders[k](flood))
    photo = first.rig.capture_view(ViewCapture(quality=SHARED_SPP)).radiance
    point, normal, chart_rms = board_plane(photo, tuple(chart), scene.view)
    for k in pair:
        arrays[k].rig.project(arrays[k].rig.info.black())
    seen = {}
    for k in pair:
        a = arrays[k]
        board = _drawn_on(asked[k], a.world_to_model(point[None])[0], a.direction_to_model(normal[None])[0])
        shots = []
        for j, lf in enumerate(fringe_lightfields(a.model.array, n, n, board, size, levels[k])):
            say(f"lit by {scene.interfaces[k].name}'s fringes {j + 1} of {2 * FRINGE_SHIFTS}")
            a.rig.project(encoders[k](lf))
            shots.append(first.rig.capture_view(ViewCapture(quality=SHARED_SPP)).radiance)
        a.rig.project(a.rig.info.black())
        px, coords = _sample_valid(decode_fringes(shots, board, size, scene.view, a.model_to_world))
        if len(px) < 50:
            raise PoseError(f"shared board of {scene.interfaces[0].name} and {scene.interfaces[i].name} at "
                            f"{100 * depth:.0f} cm: only {len(px)} view camera pixels saw "
                            f"{scene.interfaces[k].name}'s fringes clearly")
        inv = np.linalg.inv(a.to_world)
        seen[k] = {"drawn": board.centre + coords[:, :1] * board.ex + coords[:, 1:] * board.ey, "px": px,
                   "world": rigid_points(inv, backproject(scene.view, px, point, normal)),
                   "point": rigid_points(inv, point[None])[0],
                   "normal": rigid_vectors(a.to_world, normal[None], back=True)[0], "chart_rms": chart_rms}
    return seen


def _board_in(board: BoardPattern, array: _Array) -> BoardPattern:
    """A world-frame board in an array's model frame (its own pose)."""
    centre = array.world_to_model(board.centre[None])[0]
    ex, ey, normal = plane_axes(array.direction_to_model(board.normal[None])[0])
    return BoardPattern(centre, normal, ex, ey, board.squares, board.square_m)


def _carried(first: _Array, other: _Array, first_shared: ArrayPose, other_shared: ArrayPose) -> ArrayPose:
    """``other``'s pose (model frame -> its interface frame) that puts it where the shared boards put it relative to
    ``first``, with ``first`` where its own pose step put it: the map shared-world -> first's own world applied to
    where the shared boards saw ``other``'s lenslets, fitted by the pose family (:func:`solve_array_pose`)."""
    centres = other.model.array.centres
    X = np.concatenate([np.column_stack([centres, np.zeros(len(centres))]),
                        np.column_stack([centres, np.full(len(centres), other.model.array.focal_length)])])
    seen = rigid_points(other.to_world, other_shared.model_to_world(X))            # world, as the shared boards saw
    in_first = first_shared.world_to_model(rigid_points(np.linalg.inv(first.to_world), seen))
    world = rigid_points(first.to_world, first.pose.model_to_world(in_first))       # first where its own pose has it
    return solve_array_pose(X, rigid_points(np.linalg.inv(other.to_world), world), start=other_shared)


def _moved_mm(array: _Array, own: ArrayPose, tied: ArrayPose) -> float:
    """RMS distance between the lenslet centres placed by ``own`` and by ``tied``, millimetres."""
    c = array.model.array.centres
    X = np.column_stack([c, np.zeros(len(c))])
    return float(1000 * np.sqrt(np.mean(np.sum((own.model_to_world(X) - tied.model_to_world(X)) ** 2, axis=1))))
