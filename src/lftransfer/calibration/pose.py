"""Global pose: where the lens array stands in the view camera's world (paper, section 4.2).

The rig renders light fields whose rays draw phase-shifted sinusoidal fringes on a plane at a chosen depth in
front of the array, in the frame its calibration so far defines (the *model frame*: the rig file's nominal array,
whose pitch is the unit of length), and projects them on a board held there; the view camera photographs them.
The fringes' phase at each pixel is the board coordinate drawn there, whatever the lenslets' blur (structured
light), so every pixel on the board pairs a model-frame point with a world point: the pixel's ray meets the
board's plane, measured from the chessboard printed on it.

Those pairs give the array's pose in the world:

    X_world = R_tilt(a_x, a_y) (s R_z(theta) X_model + (o_x, o_y, 0))

with ``R_tilt`` the array plane's out-of-plane tilt about the world origin, ``theta`` its in-plane rotation,
``o`` its in-plane offset and ``s`` the ratio of true to nominal pitch (the lenslet calibration fixes the rig
only up to this similarity), by least squares over boards at two depths (their parallax fixes the tilt).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
from scipy.optimize import least_squares

from lftransfer.calibration.chart import CHART, PoseError, board_plane
from lftransfer.lightfield import LightField
from lftransfer.lightfield.fringes import (FRINGE_PERIOD_M, FRINGE_SHIFTS, BoardPattern, FringeDecoding, decode_fringes,
                                          fringe_lightfields)
from lftransfer.optics import LensArray, LensletDevice
from lftransfer.optics.geometry import (backproject, crosses_rectangle, plane_axes, project, rotation_2d, rotation_xy,
                                        rotation_z, view_camera)
from lftransfer.rig.base import Rig
from lftransfer.rig.model import RigModel
from lftransfer.rig.requests import Board, ViewCapture

__all__ = ["BOARD_CLEARANCE_M", "BOARD_MAX_OBLIQUITY_DEG", "CHART", "FRINGE_PERIOD_M", "FRINGE_SHIFTS",
           "POSE_DEPTHS", "POSE_ROUNDS", "apply_pose", "ArrayPose", "board_pattern", "BoardPattern",
           "calibrate_pose", "corner_landing", "decode_fringes", "fringe_lightfields", "FringeDecoding", "PoseError",
           "sees_lit_side", "solve_array_pose", "view_camera"]


BOARD_MAX_OBLIQUITY_DEG = 50.0   # an opaque board turned halfway between the array and the view camera is seen at
                                 # most this obliquely (else the calibration asks for a translucent one)
BOARD_CLEARANCE_M = 0.02         # a translucent board keeps its nearest corner this far in front of the array


def sees_lit_side(view, depth: float = 0.1) -> bool:
    """Whether the view camera sees the face of a board ``depth`` in front of the array's centre that the array
    lights, turned halfway between them, at most :data:`BOARD_MAX_OBLIQUITY_DEG` obliquely. A camera beside the
    array (the paper's) does; one in front of the board, looking back at the array, does not: it sees such a board
    through a translucent screen (:func:`board_pattern`'s ``translucent``)."""
    to_cam = np.asarray(view.origin, np.float64) - np.array([0.0, 0.0, float(depth)])
    cos = -to_cam[2] / np.linalg.norm(to_cam)                       # against the array's light, (0, 0, -1)
    return bool(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))) <= 2 * BOARD_MAX_OBLIQUITY_DEG)


def board_pattern(view, depth: float = 0.2, squares=(6, 5), square_m: float = 0.045, *, translucent: bool = False,
                  extent: tuple[float, float] | None = None, walls: np.ndarray | None = None) -> BoardPattern:
    """The board plane: centred on the array's axis at ``depth``, turned halfway towards the view camera.

    Facing both the array (which lights it) and the view camera (which photographs it) keeps the board well lit
    and not too foreshortened. A ``translucent`` board (a rear-projection screen, for a view camera in front of it:
    :func:`sees_lit_side`) is seen from behind: it faces halfway between the array and the direction away from the
    camera, stands on the camera's line of sight to its target (in the middle of its view), and moves away from
    the array until a board of ``extent`` (width, height, metres) keeps :data:`BOARD_CLEARANCE_M` from it.
    ``walls``: (N, 4) the other light field interfaces' planes in this array's frame (``n . x + d > 0`` on their
    real side, :func:`lftransfer.scenes.interfaces.walls`); a screen that would reach within
    :data:`BOARD_CLEARANCE_M` of one on the camera's line of sight stays on the array's axis.
    """
    centre = np.array([0.0, 0.0, float(depth)])
    to_cam = np.asarray(view.origin, np.float64) - centre
    to_cam = to_cam / np.linalg.norm(to_cam)
    if not translucent:
        ex, ey, normal = plane_axes(to_cam + np.array([0.0, 0.0, -1.0]))
        return BoardPattern(centre, normal, ex, ey, tuple(squares), float(square_m))
    ex, ey, normal = plane_axes(np.array([0.0, 0.0, -1.0]) - to_cam)
    if extent is not None:
        reach = 0.5 * (abs(ex[2]) * float(extent[0]) + abs(ey[2]) * float(extent[1]))
        centre[2] = max(centre[2], BOARD_CLEARANCE_M + reach)
    origin, target = np.asarray(view.origin, np.float64), np.asarray(view.target, np.float64)
    if abs(origin[2] - target[2]) > 1e-9:
        sight = centre.copy()
        sight[:2] = (target + (origin - target) * (centre[2] - target[2]) / (origin[2] - target[2]))[:2]
        moved = BoardPattern(sight, normal, ex, ey, tuple(squares), float(square_m))
        if _clear(moved, extent, walls):
            return moved
    return BoardPattern(centre, normal, ex, ey, tuple(squares), float(square_m))


def _clear(board: BoardPattern, extent: tuple[float, float] | None, walls: np.ndarray | None) -> bool:
    """Whether ``board`` of ``extent`` (its centre alone for None) keeps :data:`BOARD_CLEARANCE_M` on the real side
    of every plane of ``walls`` ((N, 4), or None: no walls)."""
    if walls is None or len(walls) == 0:
        return True
    corners = board.outline((0.0, 0.0) if extent is None else extent)
    planes = np.asarray(walls, np.float64).reshape(-1, 4)
    return bool(np.all(corners @ planes[:, :3].T + planes[:, 3] >= BOARD_CLEARANCE_M))


PANEL_STEP_M = 0.005       # a board a camera behind the array's plane would see partly through the array's panel
PANEL_MAX_SHIFT_M = 0.15   # moves away from the array in these steps, at most this far


def panel_shift(view, depth: float, extent: tuple[float, float], array_extent: tuple[float, float, float, float],
                *, translucent: bool = False, walls: np.ndarray | None = None) -> float:
    """How much farther from the array than ``depth`` a board must stand for the view camera to see all of it past
    the array's panel (0 for a camera in front of or in the array's plane, whose rays to the real side never cross
    the panel).

    A camera behind the plane, beside the array, sees the real side over the array's edge; a board turned towards it
    dips its far edge towards the array, and the rays to that edge cross the plane inside the array's rectangle,
    where the panel hides it. Then the board (:func:`board_pattern` at ``depth`` plus the shift) moves away in
    :data:`PANEL_STEP_M` steps until the rays to its corners cross the plane outside ``array_extent`` (xmin, xmax,
    ymin, ymax) or :data:`PANEL_MAX_SHIFT_M` is reached."""
    origin = np.asarray(view.origin, np.float64)
    if origin[2] >= 0:
        return 0.0
    shift = 0.0
    while shift <= PANEL_MAX_SHIFT_M:
        board = board_pattern(view, depth + shift, translucent=translucent, extent=extent, walls=walls)
        corners = board.outline(extent)
        if not crosses_rectangle(origin, corners - origin, array_extent).any():
            return shift
        shift += PANEL_STEP_M
    return PANEL_MAX_SHIFT_M


@dataclass
class ArrayPose:
    """Pose of the lens array in the world, relative to the model frame of the lenslet calibration.

    Attributes:
        tilt: (about x, about y) radians, the array plane's tilt about the world origin.
        rotation: in-plane rotation, radians.
        offset: (2,) in-plane offset, metres.
        scale: true pitch / nominal pitch.
        rms_px: reprojection RMS of the measured points (projected corners or fringe points), view camera pixels.
        corners_px: (N, 2) measured points (a sample of them, for the report); reprojected (N, 2) their
            reprojection.
        pnp_rms_px: reprojection RMS of the printed chessboard's pose (``cv2.solvePnP``), pixels.
        residual_mm: RMS distance between the measured points and the fitted pose's, millimetres.
    """

    tilt: tuple[float, float]
    rotation: float
    offset: tuple[float, float]
    scale: float
    rms_px: float = float("nan")
    corners_px: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    reprojected: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    pnp_rms_px: float = float("nan")
    residual_mm: float = float("nan")

    def model_to_world(self, X: np.ndarray) -> np.ndarray:
        """(N, 3) model-frame points -> world points."""
        local = self.scale * np.asarray(X, np.float64) @ rotation_z(self.rotation).T + np.array([*self.offset, 0.0])
        return local @ rotation_xy(self.tilt).T

    def world_to_model(self, X: np.ndarray) -> np.ndarray:
        """(N, 3) world points -> model-frame points (the inverse of :meth:`model_to_world`)."""
        local = np.asarray(X, np.float64) @ rotation_xy(self.tilt) - np.array([*self.offset, 0.0])
        return local @ rotation_z(self.rotation) / self.scale

    def direction_to_model(self, v: np.ndarray) -> np.ndarray:
        """(N, 3) world directions -> unit model-frame directions."""
        d = np.asarray(v, np.float64) @ rotation_xy(self.tilt) @ rotation_z(self.rotation)
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def to_json(self) -> dict:
        return {"tilt_deg": np.degrees(self.tilt).tolist(), "rotation_deg": float(np.degrees(self.rotation)),
                "offset_mm": (np.asarray(self.offset) * 1000).tolist(), "scale": self.scale,
                "rms_px": self.rms_px, "pnp_rms_px": self.pnp_rms_px, "residual_mm": self.residual_mm}

    @classmethod
    def from_json(cls, data: dict) -> "ArrayPose":
        return cls(tilt=tuple(np.radians(data["tilt_deg"]).tolist()), rotation=float(np.radians(data["rotation_deg"])),
                   offset=tuple((np.asarray(data["offset_mm"], float) / 1000).tolist()), scale=float(data["scale"]),
                   rms_px=float(data.get("rms_px", "nan")), pnp_rms_px=float(data.get("pnp_rms_px", "nan")),
                   residual_mm=float(data.get("residual_mm", "nan")))


def solve_array_pose(corners_model: np.ndarray, corners_world: np.ndarray, *,
                     landing: Callable[[ArrayPose], np.ndarray] | None = None,
                     start: ArrayPose | None = None) -> ArrayPose:
    """The array pose (similarity with the tilt, rotation, offset and scale of :class:`ArrayPose`).

    Args:
        corners_model: (N, 3) model-frame corner positions.
        corners_world: (N, 3) the same corners measured in the world.
        landing: where the corners really are in the model frame for a candidate pose (N, 3), when that depends on
            the pose (corners drawn by light on a board whose world plane is measured: :func:`corner_landing`);
            None: at ``corners_model``.
        start: initial pose (default: the identity).

    Returns:
        ArrayPose; ``rms_px`` is left for the caller, ``residual_mm`` holds the 3-D fit's RMS.
    """
    if len(corners_model) < 4:
        raise PoseError(f"only {len(corners_model)} projected corners were found; at least 4 are needed")

    def pose(p):
        return ArrayPose(tilt=(p[0], p[1]), rotation=p[2], offset=(p[3], p[4]), scale=1.0 + p[5])

    def residual(p):
        candidate = pose(p)
        model = corners_model if landing is None else landing(candidate)
        return (candidate.model_to_world(model) - corners_world).ravel()

    x0 = np.zeros(6) if start is None else np.array([*start.tilt, start.rotation, *start.offset, start.scale - 1.0])
    sol = least_squares(residual, x0, x_scale=1e-3, method="lm")
    out = pose(sol.x)
    out.residual_mm = float(1000 * np.sqrt(np.mean(np.sum(residual(sol.x).reshape(-1, 3) ** 2, axis=1))))
    return out


def apply_pose(model: RigModel, pose: ArrayPose) -> RigModel:
    """The rig model in the world: the model-frame array carried by the pose (devices follow).

    The model frame's focal plane maps to the calibrated one by the 2-D similarity
    ``q -> s R(theta) q + o``; each device's homography absorbs its inverse, so its pixels keep their rays.
    """
    a = model.array
    s, th = pose.scale, pose.rotation
    array = LensArray(lattice=a.lattice, rows=a.rows, cols=a.cols, pitch=a.pitch * s, focal_length=a.focal_length * s,
                      aperture=a.aperture, offset=tuple(float(v) for v in pose.offset), rotation=float(th))
    sim = np.eye(3)
    sim[:2, :2] = s * rotation_2d(th)
    sim[:2, 2] = pose.offset
    inv = np.linalg.inv(sim)

    def moved(dev: LensletDevice) -> LensletDevice:
        return replace(dev, homography=dev.homography @ inv)

    return replace(model, array=array, camera=replace(model.camera, device=moved(model.camera.device)),
                   projector=replace(model.projector, device=moved(model.projector.device)),
                   tilt=(float(pose.tilt[0]), float(pose.tilt[1])))


def corner_landing(array: LensArray, corners: np.ndarray, point: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Where the projected corners land on a board that is not where they were drawn (model frame).

    A corner drawn at X is the meeting point of the rays from every lenslet whose window holds the direction
    towards X. On a board plane through ``point`` with ``normal`` (off the drawing plane by the operator's hand
    error and the model frame's scale), those rays spread into a small blur; the corner seen on the board is the
    blur's centroid: the mean of the rays' intersections with the plane.

    Args:
        array: the lens array in the model frame.
        corners: (N, 3) drawn corner positions, model frame.
        point, normal: (3,) the board plane, model frame.

    Returns:
        (N, 3) landing points, model frame (``corners`` itself for a lenslet-free corner).
    """
    c = array.centres3d[None]                                            # (1, K, 3)
    d = corners[:, None, :] - c                                          # (N, K, 3)
    with np.errstate(divide="ignore", invalid="ignore"):
        offsets = -array.focal_length * d[..., :2] / d[..., 2:3]         # focal-plane offsets of those directions
        lit = (d[..., 2] > 0) & array.in_cell(np.nan_to_num(offsets, nan=1e9))
        lam = ((point - c) @ normal) / (d @ normal)                      # (N, K)
    hits = c + lam[..., None] * d
    lit &= np.isfinite(lam) & (lam > 0)
    n = lit.sum(axis=1)
    mean = np.where(lit[..., None], hits, 0.0).sum(axis=1) / np.maximum(n, 1)[:, None]
    return np.where((n > 0)[:, None], mean, corners)


POSE_DEPTHS = (0.07, 0.12)      # metres: the boards' distances from the array (two, for parallax)
POSE_ROUNDS = 3                 # later rounds draw the fringes on each board where the previous round measured
                                # it (on seed 5: 1.81 mm / 0.67 deg after one round, 0.71 / 0.30 after two, 0.27 / 0.11)


def _drawn_on(board: BoardPattern, point: np.ndarray, normal: np.ndarray) -> BoardPattern:
    """The same checkerboard moved onto the plane through ``point`` with ``normal`` (model frame): its centre is
    the asked-for centre's foot on that plane; the normal keeps the asked-for side."""
    n = np.asarray(normal, np.float64) / np.linalg.norm(normal)
    if n @ board.normal < 0:
        n = -n
    centre = board.centre - ((board.centre - point) @ n) * n
    ex, ey, n = plane_axes(n)
    return BoardPattern(centre, n, ex, ey, board.squares, board.square_m)


@dataclass(frozen=True)
class _Shot:
    """How each pose board is lit and photographed: the lit rectangle (width, height, metres), the printed chart,
    the fringes' peak radiance, the photographs' samples per pixel, the model's encoder and the flood light field
    (half the peak) the chart is photographed under."""

    size: tuple[float, float]
    chart: tuple
    level: float
    spp: int
    encoder: object
    flood: LightField


def _photograph_board(rig: Rig, model: RigModel, scene, asked: BoardPattern, pose: "ArrayPose | None",
                      screen: bool, shot: _Shot, say: Callable[[str], None]) -> dict:
    """One board of a pose round: asked for, its plane found from the chart under a flood light field, the fringes
    drawn on it (on its measured plane, carried into the model frame by ``pose``, from the second round on) and
    decoded into view pixels and the model-frame points drawn there."""
    n = scene.rig.angular_samples
    size, chart, encoder, flood = shot.size, shot.chart, shot.encoder, shot.flood
    rig.setup(Board(centre=tuple(asked.centre), normal=tuple(asked.normal), size=size, chart=tuple(chart),
                    translucent=screen))
    images = {}
    say("photographed with the flood light field")
    rig.project(encoder(flood))
    images["flood"] = rig.capture_view(ViewCapture(quality=shot.spp)).radiance
    point, normal, chart_rms = board_plane(images["flood"], tuple(chart), scene.view, screen=screen)
    board = asked if pose is None else _drawn_on(asked, pose.world_to_model(point[None])[0],
                                                pose.direction_to_model(normal[None])[0])
    fringes = fringe_lightfields(model.array, n, n, board, size, shot.level)
    shots = []
    for j, lf in enumerate(fringes):
        say(f"photographed with fringes {j + 1} of {len(fringes)}")
        rig.project(encoder(lf))
        shots.append(rig.capture_view(ViewCapture(quality=shot.spp)).radiance)
    rig.project(rig.info.black())
    images["fringes"] = shots[0]
    dec = decode_fringes(shots, board, size, scene.view, None if pose is None else pose.model_to_world)
    px, coords = _sample_valid(dec)
    if len(px) < 50:
        raise PoseError(f"board at {100 * asked.centre[2]:.0f} cm: only {len(px)} view camera pixels saw the "
                        "projected fringes clearly; is the board in view and lit?")
    drawn = board.centre + coords[:, :1] * board.ex + coords[:, 1:] * board.ey
    # found: (H, W) bool, normalised: (H, W) cos(phase), for the report
    return {"asked": asked, "board": board, "point": point, "normal": normal, "chart_rms": chart_rms, "px": px,
            "found": dec.valid, "images": images, "normalised": dec.wrapped,
            "world": backproject(scene.view, px, point, normal), "drawn": drawn}


def _board_diagnostics(b: dict, pose: "ArrayPose") -> dict:
    """A board's entry of the report: its photographs, decoded pixels and its placement error as measured."""
    n_m = pose.direction_to_model(b["normal"][None])[0]
    if n_m @ b["asked"].normal < 0:                   # the chart's normal may face either way
        n_m = -n_m
    placement = {"depth_mm": float(1000 * (pose.world_to_model(b["point"][None])[0] - b["asked"].centre) @ n_m),
                 "tilt_deg": float(np.degrees(np.arccos(np.clip(n_m @ b["asked"].normal, -1.0, 1.0))))}
    return {"images": b["images"], "normalised": b["normalised"], "found": b["found"],
            "board_placement": placement, "depth_m": float(b["asked"].centre[2])}


def calibrate_pose(rig: Rig, model: RigModel, scene, *, depths=POSE_DEPTHS, rounds: int = POSE_ROUNDS,
                   chart=CHART, spp: int = 16, walls: np.ndarray | None = None,
                   progress: Callable[[str], None] | None = None) -> tuple[ArrayPose, dict]:
    """Ask for a board at each depth, find its plane, project phase-shifted fringes on it, solve the pose from all
    boards at once; then again, with the fringes drawn on each board where it stands.

    The board is asked for where the fringes are drawn (``depth`` in front of the array, turned towards the view
    camera); the operator puts it there only roughly. Its plane is measured in the world from the printed
    chessboard. Fringes along the board's two axes (:func:`fringe_lightfields`) give every view camera pixel on it
    the model-frame point drawn there (:func:`decode_fringes`): thousands of correspondences per board, each
    immune to the lenslets' blur. A point drawn by light lands where its rays meet the real board
    (:func:`corner_landing`), which depends on the pose: the fit solves the pose with each point where it lands for
    the candidate pose, so the board's placement errors go into the fit, not into the pose. Seen on one board,
    rays along the array's axis hide how the array is tilted (a tilt and an offset move every point alike); boards
    at two depths see the rays' parallax and fix the tilt.

    A board a few millimetres off the drawing plane sees each point as the overlap of several lenslets' slightly
    different images (out of focus), which the landing model describes only on average. From the second round on,
    the boards are asked for again, and the fringes are drawn on each board's measured plane carried into the
    model frame by the previous round's pose: in focus up to that pose's error. The last round gives the pose.

    Args:
        rig: the rig; it is asked for a :class:`~lftransfer.rig.requests.Board` with a printed chessboard at each
            depth (``rounds`` times) and shows the light fields on it.
        model: the calibrated rig in the model frame (lenslets, projector mapping, distortion).
        scene: the scene (view camera, angular samples).
        depths: distances of the boards' centres from the array, metres (model frame).
        rounds: rounds of boards (1: the fringes drawn where the board was asked for, only).
        chart: (columns, rows, square size in metres) of the printed chessboard; the board is two squares larger
            each way, and the fringes light all of it.
        spp: view camera quality (samples per pixel of a simulated camera) of the calibration photographs.
        walls: the other light field interfaces' planes in this array's frame (:func:`board_pattern`), or None.
        progress: called with a message per capture.

    Returns:
        (ArrayPose, diagnostics: per board of the last round the view images, the decoded pixels and its placement
        error as measured, for the report; the first board's also at the top level; ``rounds``: the pose after
        each). ``pose.corners_px`` and ``pose.reprojected`` keep an even sample of the points for the report;
        ``pose.rms_px`` is over all of them.
    """
    if rounds < 1:
        raise ValueError(f"rounds: expected at least 1, got {rounds}")
    n = scene.rig.angular_samples
    level = 0.9 * model.projector.max_radiance
    flood = LightField.zeros(model.array, n, n)
    flood.data[...] = 0.5 * level
    size = ((chart[0] + 2) * chart[2], (chart[1] + 2) * chart[2])
    shot = _Shot(size, chart, level, spp, model.encoder(n, n), flood)
    pose: ArrayPose | None = None
    history = []
    # a view camera in front of the boards sees them through translucent screens, which may have to move away from
    # the array (board_pattern); every board moves as far as the nearest one, so the depths keep their parallax
    screen = not sees_lit_side(scene.view, min(depths))
    shift = board_pattern(scene.view, min(depths), translucent=screen, extent=size, walls=walls).centre[2] - min(depths)
    # a camera behind the array's plane sees the boards past the array's panel: they move away until it hides none
    shift += panel_shift(scene.view, min(depths) + shift, size, model.array.extent(), translucent=screen,
                         walls=walls)
    for r in range(rounds):
        boards = []
        for depth in depths:
            asked = board_pattern(scene.view, depth + shift, translucent=screen, extent=size, walls=walls)
            tag = f"pose round {r + 1}: board at {100 * asked.centre[2]:.0f} cm" if rounds > 1 else \
                f"pose: board at {100 * asked.centre[2]:.0f} cm"
            boards.append(_photograph_board(rig, model, scene, asked, pose, screen, shot,
                                            lambda msg: progress and progress(f"{tag} {msg}")))
        pose = _solve_boards(model.array, boards, scene.view, start=pose)
        history.append(pose.to_json())

    per_board = [_board_diagnostics(b, pose) for b in boards]
    shown = np.concatenate([np.linspace(0, len(b["px"]) - 1, 24).round().astype(int) + sum(len(c["px"]) for c in
                                                                                          boards[:i])
                            for i, b in enumerate(boards)])
    pose.corners_px, pose.reprojected = pose.corners_px[shown], pose.reprojected[shown]
    first = per_board[0]
    worst = max(per_board, key=lambda d: abs(d["board_placement"]["depth_mm"]))["board_placement"]
    return pose, {**first, "board_placement": worst, "boards": per_board, "rounds": history}


def _sample_valid(dec: FringeDecoding, most: int = 3000) -> tuple[np.ndarray, np.ndarray]:
    """Valid pixels on a regular grid, at most about ``most``: (N, 2) pixels and (N, 2) board coordinates."""
    ys, xs = np.nonzero(dec.valid)
    stride = max(1, int(np.ceil(np.sqrt(len(ys) / most))))
    keep = (ys % stride == 0) & (xs % stride == 0)
    ys, xs = ys[keep], xs[keep]
    return np.stack([xs, ys], 1).astype(np.float64), dec.coords[ys, xs]


def _solve_boards(array: LensArray, boards: list[dict], view, start: ArrayPose | None) -> ArrayPose:
    """The pose from one round of boards: each corner where its rays land on its board's measured plane."""

    def landing(candidate: ArrayPose) -> np.ndarray:
        return np.concatenate([corner_landing(array, b["drawn"], candidate.world_to_model(b["point"][None])[0],
                                              candidate.direction_to_model(b["normal"][None])[0]) for b in boards])

    drawn = np.concatenate([b["drawn"] for b in boards])
    world = np.concatenate([b["world"] for b in boards])
    pose = solve_array_pose(drawn, world, landing=landing, start=start or solve_array_pose(drawn, world))
    pose.corners_px = np.concatenate([b["px"] for b in boards])
    pose.reprojected = project(view, pose.model_to_world(landing(pose)))
    pose.rms_px = float(np.sqrt(np.mean(np.sum((pose.reprojected - pose.corners_px) ** 2, axis=1))))
    pose.pnp_rms_px = float(max(b["chart_rms"] for b in boards))
    return pose
