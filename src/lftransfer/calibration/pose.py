"""Global pose: where the lens array stands in the view camera's world (paper, section 4.2).

The rig renders the light field of a checkerboard plane lying at a chosen depth in front of the array, in the
frame its calibration so far defines (the *model frame*: the rig file's nominal array, whose pitch is the unit
of length), and projects it. The rays of all lenslets meet on that plane, so a diffuse board held there shows a
sharp checkerboard, which the view camera photographs. The pattern and its inverse are both projected: their
normalised difference ``(A - B) / (A + B)`` no longer depends on how many lenslets light each point, and its
saddle points are the corners.

The corners' model-frame positions and their pixels give the array's pose in the world:

    X_world = R_tilt(a_x, a_y) (s R_z(theta) X_model + (o_x, o_y, 0))

with ``R_tilt`` the array plane's out-of-plane tilt about the world origin, ``theta`` its in-plane rotation,
``o`` its in-plane offset and ``s`` the ratio of true to nominal pitch (the lenslet calibration fixes the rig
only up to this similarity). ``cv2.solvePnP`` gives a first rigid pose at the nominal scale; a least-squares
refinement of the six parameters above follows. A camera alone cannot tell a larger array further away from the
nominal one (vision is up to scale); the constraint that the array's centre lies in its own plane through the
world origin, where the rig is mounted, fixes the scale.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable

import cv2
import numpy as np
from scipy.optimize import least_squares

from lftransfer.lightfield import LightField
from lftransfer.optics import LensArray, LensletDevice
from lftransfer.optics.geometry import backproject, plane_axes, project, rotation_xy, rotation_z, view_camera
from lftransfer.rig.base import Rig
from lftransfer.rig.model import RigModel
from lftransfer.rig.requests import Board, ViewCapture

__all__ = ["POSE_DEPTHS", "POSE_ROUNDS", "ArrayPose", "BoardPattern", "PoseError", "apply_pose", "board_pattern", "calibrate_pose",
           "checkerboard_lightfield", "corner_landing", "find_board_corners", "solve_array_pose", "view_camera"]


class PoseError(ValueError):
    """The board's corners could not be found or the pose could not be solved."""


@dataclass(frozen=True)
class BoardPattern:
    """A checkerboard plane in front of the array, in the model frame.

    Attributes:
        centre: (3,) metres (z > 0: the real side).
        normal: (3,) unit normal, towards the array and the view camera.
        ex, ey: (3,) unit in-plane axes.
        squares: (columns, rows) of squares.
        square_m: square size, metres.
    """

    centre: np.ndarray
    normal: np.ndarray
    ex: np.ndarray
    ey: np.ndarray
    squares: tuple[int, int] = (6, 5)
    square_m: float = 0.045

    def corners(self) -> np.ndarray:
        """(N, 3) model-frame positions of the inner corners, row-major."""
        b = self.board_2d()
        return self.centre + b[:, :1] * self.ex + b[:, 1:2] * self.ey

    def board_2d(self) -> np.ndarray:
        """(N, 3) the same corners in the board's own plane (z = 0), for ``cv2.solvePnP``."""
        cols, rows = self.squares
        i, j = np.meshgrid(np.arange(1, cols) - cols / 2, np.arange(1, rows) - rows / 2)
        return np.stack([i.ravel(), j.ravel(), np.zeros(i.size)], 1) * self.square_m


def board_pattern(view, depth: float = 0.2, squares=(6, 5), square_m: float = 0.045) -> BoardPattern:
    """The board plane: centred on the array's axis at ``depth``, turned halfway towards the view camera.

    Facing both the array (which lights it) and the view camera (which photographs it) keeps the corners
    well lit and not too foreshortened.
    """
    centre = np.array([0.0, 0.0, float(depth)])
    to_cam = np.asarray(view.origin, np.float64) - centre
    normal = to_cam / np.linalg.norm(to_cam) + np.array([0.0, 0.0, -1.0])
    ex, ey, normal = plane_axes(normal)
    return BoardPattern(centre, normal, ex, ey, tuple(squares), float(square_m))


def checkerboard_lightfield(array: LensArray, U: int, V: int, board: BoardPattern,
                            radiance: float) -> tuple[LightField, LightField]:
    """The light field whose rays draw the checkerboard on the board plane, and its inverse.

    Each sample (k, d) is the ray leaving lenslet k's centre along +d into the real side; where it meets the
    board plane inside the pattern, it carries ``radiance`` on white squares (pattern) or black ones
    (inverse), else nothing.

    Returns:
        pattern, inverse: LightField (K, V, U, 3) float32 radiance.
    """
    lf = LightField.zeros(array, U, V)
    d = lf.directions()                                                   # (V, U, 3)
    c = array.centres3d[:, None, None, :]                                 # (K, 1, 1, 3)
    denom = d @ board.normal                                              # (V, U)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((board.centre - c) @ board.normal) / denom                   # (K, V, U)
    x = c + t[..., None] * d[None]
    rel = x - board.centre
    a, b = rel @ board.ex / board.square_m, rel @ board.ey / board.square_m
    cols, rows = board.squares
    inside = (t > 0) & (np.abs(a) < cols / 2) & (np.abs(b) < rows / 2) & lf.mask()[None]
    white = (np.floor(a + cols / 2).astype(int) + np.floor(b + rows / 2).astype(int)) % 2 == 0
    pattern, inverse = lf, LightField.zeros(array, U, V)
    pattern.data[...] = (radiance * (inside & white))[..., None]
    inverse.data[...] = (radiance * (inside & ~white))[..., None]
    return pattern, inverse


def find_board_corners(pattern_img: np.ndarray, inverse_img: np.ndarray, board: BoardPattern, view,
                       plane_to_world: Callable[[np.ndarray], np.ndarray] | None = None
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixels of the projected checkerboard's inner corners, by aligning the whole pattern at once.

    The lenslets' apertures blur the projected pattern by about their pitch, nearly a square: its normalised
    difference ``N = (A - B) / (A + B)`` is then close to ``sin(pi a) sin(pi b)`` in the board's square
    coordinates (a, b), whose zeros are the square edges and whose saddles are the corners. A template of that
    function, drawn where the corners are predicted, is aligned to N by a homography (``cv2.findTransformECC``,
    which is blind to contrast); the corners are the predicted ones carried by that homography. The blur is
    symmetric about every corner, so it moves none.

    Args:
        pattern_img, inverse_img: (H, W, 3) view camera images (linear radiance) with the pattern and with its
            inverse projected.
        board: the projected pattern.
        view: ``ViewConfig``.
        plane_to_world: where the board plane is predicted (model frame -> world); identity if None.

    Returns:
        corners (N, 2) float64 pixels of ``board.corners()``, found (N,) bool, and the normalised difference
        image N (H, W) float32 (for the report).
    """
    a_img, b_img = pattern_img.mean(axis=2), inverse_img.mean(axis=2)
    total = a_img + b_img
    lit = total > 0.05 * np.percentile(total, 99.5)
    norm = np.where(lit, (a_img - b_img) / np.where(lit, total, 1.0), 0.0).astype(np.float32)
    h, w = norm.shape
    to_world = plane_to_world or (lambda X: X)
    # predicted board plane in the world, and each pixel's square coordinates on it
    origin = to_world(board.centre[None])[0]
    ex = to_world((board.centre + board.ex)[None])[0] - origin
    ey = to_world((board.centre + board.ey)[None])[0] - origin
    normal = np.cross(ex, ey)
    ys, xs = np.mgrid[0:h, 0:w]
    px = np.stack([xs.ravel(), ys.ravel()], 1).astype(np.float64)
    X = backproject(view, px, origin, normal / np.linalg.norm(normal))
    cols, rows = board.squares
    a = ((X - origin) @ ex) / (ex @ ex) / board.square_m + cols / 2
    b = ((X - origin) @ ey) / (ey @ ey) / board.square_m + rows / 2
    template = (np.sin(np.pi * a) * np.sin(np.pi * b)).reshape(h, w).astype(np.float32)
    inner = ((a > 0.5) & (a < cols - 0.5) & (b > 0.5) & (b < rows - 0.5)).reshape(h, w) & lit
    corners_pred = project(view, to_world(board.corners()))
    if inner.sum() < 100:
        return corners_pred, np.zeros(len(corners_pred), bool), norm
    if np.mean(template[inner] * norm[inner]) < 0:      # the pattern's phase: white squares where a + b is even
        template = -template
    warp = np.eye(3, dtype=np.float32)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 200, 1e-7)
    try:
        _, warp = cv2.findTransformECC(template, norm, warp, cv2.MOTION_HOMOGRAPHY, crit, inner.astype(np.uint8), 1)
    except cv2.error as exc:
        raise PoseError(f"the projected checkerboard could not be aligned in the view camera image: {exc}") from None
    p = np.concatenate([corners_pred, np.ones((len(corners_pred), 1))], 1) @ warp.astype(np.float64).T
    corners = p[:, :2] / p[:, 2:3]
    found = np.all(np.isfinite(corners), axis=1) & (corners[:, 0] >= 0) & (corners[:, 0] <= w - 1) \
        & (corners[:, 1] >= 0) & (corners[:, 1] <= h - 1)
    ix = np.clip(np.round(corners[:, 0]).astype(int), 0, w - 1)
    iy = np.clip(np.round(corners[:, 1]).astype(int), 0, h - 1)
    found &= lit[iy, ix]
    return corners, found, norm


@dataclass
class ArrayPose:
    """Pose of the lens array in the world, relative to the model frame of the lenslet calibration.

    Attributes:
        tilt: (about x, about y) radians, the array plane's tilt about the world origin.
        rotation: in-plane rotation, radians.
        offset: (2,) in-plane offset, metres.
        scale: true pitch / nominal pitch.
        rms_px: reprojection RMS of the corners, view camera pixels.
        corners_px: (N, 2) detected corners; reprojected (N, 2) their reprojection.
        pnp_rms_px: reprojection RMS of the printed chessboard's pose (``cv2.solvePnP``), pixels.
        residual_mm: RMS distance between the measured corners and the fitted pose's, millimetres.
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


def board_plane(image: np.ndarray, chart: tuple[int, int, float], view) -> tuple[np.ndarray, np.ndarray, float]:
    """The board's plane in the world from the chessboard printed on it (``cv2.solvePnP``, metric).

    Args:
        image: (H, W, 3) view camera image (linear radiance) of the flood-lit board.
        chart: (columns, rows, square size in metres) of the printed chessboard's squares.
        view: ``ViewConfig``.

    Returns:
        point (3,) and unit normal (3,) of the plane in the world, and the chart's reprojection RMS in pixels.
    """
    cols, rows, square = chart
    grey = image.mean(axis=2)
    grey8 = np.clip(255 * grey / max(np.percentile(grey, 99.5), 1e-12), 0, 255).astype(np.uint8)
    pattern = (cols - 1, rows - 1)
    ok, corners = cv2.findChessboardCorners(grey8, pattern, flags=cv2.CALIB_CB_ADAPTIVE_THRESH)
    if not ok:
        ok, corners = cv2.findChessboardCornersSB(grey8, pattern)
    if not ok:
        raise PoseError(f"the printed {cols} x {rows} chessboard was not found in the view camera image")
    corners = cv2.cornerSubPix(grey8.astype(np.float32), corners.astype(np.float32), (5, 5), (-1, -1),
                               (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)).reshape(-1, 2)
    i, j = np.meshgrid(np.arange(pattern[0]), np.arange(pattern[1]))
    obj = np.stack([i.ravel(), j.ravel(), np.zeros(i.size)], 1) * square
    K, R, t = view_camera(view)
    ok, rvec, tvec = cv2.solvePnP(obj, corners.astype(np.float64), K, None)
    if not ok:
        raise PoseError("solvePnP failed on the printed chessboard")
    proj, _ = cv2.projectPoints(obj, rvec, tvec, K, None)
    rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - corners) ** 2, axis=1))))
    rb = cv2.Rodrigues(rvec)[0]
    normal_cam, point_cam = rb[:, 2], tvec.ravel()
    return R.T @ (point_cam - t), R.T @ normal_cam, rms


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
    c, sn = np.cos(th), np.sin(th)
    sim = np.array([[s * c, -s * sn, pose.offset[0]], [s * sn, s * c, pose.offset[1]], [0.0, 0.0, 1.0]])
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
POSE_ROUNDS = 2                 # the second round draws each checkerboard on the board where it really stands


def _drawn_on(board: BoardPattern, point: np.ndarray, normal: np.ndarray) -> BoardPattern:
    """The same checkerboard moved onto the plane through ``point`` with ``normal`` (model frame): its centre is
    the asked-for centre's foot on that plane; the normal keeps the asked-for side."""
    n = np.asarray(normal, np.float64) / np.linalg.norm(normal)
    if n @ board.normal < 0:
        n = -n
    centre = board.centre - ((board.centre - point) @ n) * n
    ex, ey, n = plane_axes(n)
    return BoardPattern(centre, n, ex, ey, board.squares, board.square_m)


def calibrate_pose(rig: Rig, model: RigModel, scene, *, depths=POSE_DEPTHS, rounds: int = POSE_ROUNDS,
                   squares=(5, 4), square_m: float = 0.028, chart=(7, 5, 0.022), spp: int = 16,
                   progress: Callable[[str], None] | None = None) -> tuple[ArrayPose, dict]:
    """Ask for a board at each depth, find its plane, project the checkerboard light field and its inverse on it,
    solve the pose from all boards at once; then again, with the pattern drawn on each board where it stands.

    The board is asked for where the checkerboard is drawn (``depth`` in front of the array, turned towards the
    view camera); the operator puts it there only roughly. Its plane is measured in the world from the printed
    chessboard. A corner drawn by light lands where its rays meet the real board (:func:`corner_landing`), which
    depends on the pose: the fit solves the pose with each corner where it lands for the candidate pose, so the
    board's placement errors go into the fit, not into the pose. Seen on one board, rays along the array's axis
    hide how the array is tilted (a tilt and an offset move every corner alike); boards at two depths see the
    rays' parallax and fix the tilt.

    A board a few millimetres off the drawing plane sees each corner as the overlap of several lenslets' slightly
    different images (out of focus), which biases its detection. From the second round on, the boards are asked
    for again, and each checkerboard is drawn on the board's measured plane carried into the model frame by the
    previous round's pose: in focus up to that pose's error. The last round's corners give the pose.

    Args:
        rig: the rig; it is asked for a :class:`~lftransfer.rig.requests.Board` with a printed chessboard at each
            depth (``rounds`` times) and shows the light fields on it.
        model: the calibrated rig in the model frame (lenslets, projector mapping, distortion).
        scene: the scene (view camera, angular samples).
        depths: distances of the boards' centres from the array, metres (model frame).
        rounds: rounds of boards (1: the pattern drawn where the board was asked for, only).
        squares, square_m: layout of the projected checkerboard.
        chart: (columns, rows, square size in metres) of the printed chessboard.
        spp: view camera quality (samples per pixel of a simulated camera) of the calibration photographs.
        progress: called with a message per capture.

    Returns:
        (ArrayPose, diagnostics: per board of the last round the view images, the corners and its placement error
        as measured, for the report; the first board's also at the top level; ``rounds``: the pose after each).
    """
    if rounds < 1:
        raise ValueError(f"rounds: expected at least 1, got {rounds}")
    n = scene.rig.angular_samples
    level = 0.9 * model.projector.max_radiance
    encoder = model.encoder(n, n)
    flood = LightField.zeros(model.array, n, n)
    flood.data[...] = 0.5 * level
    size = ((chart[0] + 2) * chart[2], (chart[1] + 2) * chart[2])
    pose: ArrayPose | None = None
    history = []
    for r in range(rounds):
        boards = []
        for depth in depths:
            asked = board_pattern(scene.view, depth, squares, square_m)
            rig.setup(Board(centre=tuple(asked.centre), normal=tuple(asked.normal), size=size, chart=tuple(chart)))
            tag = f"pose round {r + 1}: board at {100 * depth:.0f} cm" if rounds > 1 else \
                f"pose: board at {100 * depth:.0f} cm"
            images = {}
            if progress:
                progress(f"{tag} photographed with the flood light field")
            rig.project(encoder(flood))
            images["flood"] = rig.capture_view(ViewCapture(quality=spp)).radiance
            point, normal, chart_rms = board_plane(images["flood"], tuple(chart), scene.view)
            board = asked if pose is None else _drawn_on(asked, pose.world_to_model(point[None])[0],
                                                        pose.direction_to_model(normal[None])[0])
            pattern, inverse = checkerboard_lightfield(model.array, n, n, board, level)
            for name, lf in (("pattern", pattern), ("inverse", inverse)):
                if progress:
                    progress(f"{tag} photographed with the {name} light field")
                rig.project(encoder(lf))
                images[name] = rig.capture_view(ViewCapture(quality=spp)).radiance
            rig.project(rig.info.black())
            px, found, norm = find_board_corners(images["pattern"], images["inverse"], board, scene.view,
                                                 None if pose is None else pose.model_to_world)
            if found.sum() < 4:
                raise PoseError(f"board at {100 * depth:.0f} cm: found {int(found.sum())} of {len(found)} "
                                "projected corners in the view camera image; is the board in view and lit?")
            boards.append({"asked": asked, "board": board, "point": point, "normal": normal, "chart_rms": chart_rms,
                           "px": px[found], "found": found, "images": images, "normalised": norm,
                           "world": backproject(scene.view, px[found], point, normal),
                           "drawn": board.corners()[found]})
        pose = _solve_boards(model.array, boards, scene.view, start=pose)
        history.append(pose.to_json())

    per_board = []
    for b in boards:
        n_m = pose.direction_to_model(b["normal"][None])[0]
        if n_m @ b["asked"].normal < 0:                   # the chart's normal may face either way
            n_m = -n_m
        placement = {"depth_mm": float(1000 * (pose.world_to_model(b["point"][None])[0] - b["asked"].centre) @ n_m),
                     "tilt_deg": float(np.degrees(np.arccos(np.clip(n_m @ b["asked"].normal, -1.0, 1.0))))}
        per_board.append({"images": b["images"], "normalised": b["normalised"], "found": b["found"],
                          "predicted": project(scene.view, pose.model_to_world(b["board"].corners())),
                          "board_placement": placement, "depth_m": float(b["asked"].centre[2])})
    first = per_board[0]
    worst = max(per_board, key=lambda d: abs(d["board_placement"]["depth_mm"]))["board_placement"]
    return pose, {**first, "board_placement": worst, "boards": per_board, "rounds": history}


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
