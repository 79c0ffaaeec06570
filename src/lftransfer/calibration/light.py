"""The real point light's position, from photographs of a board it lights (the calibration's last step).

The synthetic side is lit by a virtual twin of the real point light, which must stand where the real one
stands; the scene file's position is a measurement by hand. This step measures it from images alone:

1. **Poses.** A grey board of known size with the printed chessboard of the other steps (:data:`LIGHT_CHART`)
   is asked for at :data:`LIGHT_BOARDS` poses facing the light (as the scene file places it) and the view camera,
   clear of the array, its chessboard well inside the view and its squares wide enough in the view's pixels for
   the corner finder (:data:`MIN_SQUARE_PX`; :func:`light_board_poses`). They are chosen among a
   grid of candidates (centres in front of the array, normals turned up to 50 degrees from the direction to the
   light) greedily, by the error of the light's position that a linearised fit predicts from them: pixel noise
   (:data:`DESIGN_PIXEL_NOISE`) and each board's pose error as its chessboard measures it (corners good to
   :data:`DESIGN_CORNER_NOISE_PX`: mostly an error of depth along the view ray), which moves the light with it.
2. **Photographs.** Each board is held there (by hand: a few millimetres and about a degree off) lit by the
   real point light (:class:`~lftransfer.rig.requests.Board` with ``point_light=True``), and the view camera
   photographs it with the projector black, then white; the difference times the calibrated black level over
   white (:func:`black_share`) is the light the projector sends at black, which is taken out. Its printed
   chessboard gives where it really stands (:func:`~lftransfer.calibration.pose.chart_pose`).
3. **Fit.** Every view pixel on the board (away from its edges and from the chessboard's square edges by a
   couple of pixel footprints) is a world point X on the measured plane (normal n) with a measured radiance.
   A Lambertian board lit by a point light at p of intensity I (W/sr) has the radiance

       L(X) = a(X) rho / pi * I * n . (p - X) / |p - X|^3

   with rho the board's albedo and a(X) 1 on the plain board and on the chart's light squares, r (about 1/4)
   on its dark squares. In logarithms the unknowns are p (3), log(I rho) per channel (3, a nuisance) and
   log r (1); :func:`fit_light` solves them by nonlinear least squares (``scipy.optimize.least_squares``,
   analytic Jacobian, soft-L1 loss against stray pixels) from the scene file's position, over all boards
   at once. The residual is relative (a log radiance): its RMS is the fit's residual. Shadows (none on the
   simulated rig) are not modelled. One board fixes the light only weakly along its normal, where the light's
   distance trades against its intensity; boards turned different ways fix it.

Everything is in the scene file's world (the view camera's frame, the frame of the rig file); of the calibration
so far only the projector's black level and cross-talk are used.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from lftransfer.calibration.chart import CHART, CORNER_WINDOW_MIN_PX, PoseError, chart_pose
from lftransfer.optics.geometry import backproject, plane_axes, project, rectangle_to_world, view_camera
from lftransfer.rig.base import Rig
from lftransfer.rig.requests import Board, ViewCapture

__all__ = ["DARK_RATIO", "LIGHT_BOARDS", "LIGHT_BOARD_SIZE", "LIGHT_CHART", "LightError", "LightFit",
           "LightSamples", "black_share", "board_samples", "calibrate_light", "count_light_messages", "fit_light",
           "light_board_poses"]

LIGHT_CHART = CHART                       # the printed chessboard (columns, rows, square metres) of the other steps
LIGHT_BOARD_SIZE = ((CHART[0] + 2) * CHART[2], (CHART[1] + 2) * CHART[2])    # the pose boards: one square around
LIGHT_BOARD_ALBEDO = 0.8
LIGHT_BOARDS = 4                          # poses photographed
LIGHT_SPP = 16                            # view camera quality of the photographs (samples per pixel, simulated)
DARK_RATIO = 0.25                         # the chart's dark squares' albedo / the board's (the fit's start)
MAX_SHIFT_M = 0.05                        # a fit farther than this from the scene file's position is refused
MIN_PIXELS = 200                          # view pixels per board the fit needs
MIN_BRIGHTNESS = 0.2                      # a board lit by the light: at least this (at most 1 / this) of the
                                          # brightness the scene file's light would give it
DESIGN_PIXEL_NOISE = 0.02                 # relative noise per view pixel the pose design assumes
DESIGN_CORNER_NOISE_PX = 0.1              # noise of the chessboard's corners (view pixels) the pose design assumes
CLEARANCE_M = 0.015                       # the boards' corners stay this far in front of the array's plane
LIGHT_MIN_COS = 0.5                       # a board faces the light at least this much (cosine at its centre)
VIEW_MIN_COS = 0.5                        # ... and the view camera
MIN_SQUARE_PX = 2.0 * CORNER_WINDOW_MIN_PX  # a board's chessboard squares are at least this many view pixels across
                                            # (the narrowest, as seen): the smallest corner window reaches half-way
GRID_XY = 5                               # candidate centres per axis ...
GRID_SPAN = 0.6                           # ... over this fraction of the array's half extent
GRID_DEPTHS_M = (0.06, 0.08, 0.10, 0.12)  # ... at these distances in front of it
GRID_TURNS_DEG = (-50, -35, -20, 0, 20, 35, 50)   # normals turned from the direction to the light, about 2 axes
_MESSAGES_AFTER_BOARDS = 1                # progress messages after the photographs (the fit)

Progress = Callable[[str], None]


class LightError(RuntimeError):
    """The point light step could not measure the light (the message says which board or what, and why)."""


@dataclass(frozen=True)
class LightSamples:
    """One board's view camera pixels as the fit uses them.

    Attributes:
        points: (N, 3) world points, metres: where the pixels' rays meet the board's measured plane.
        normal: (3,) the board's unit normal, towards the light and the view camera.
        radiance: (N, 3) measured linear radiance, W m^-2 sr^-1.
        dark: (N,) bool: the point lies on a dark square of the printed chessboard.
        pixels: (N, 2) the view camera pixels (x, y).
    """

    points: np.ndarray
    normal: np.ndarray
    radiance: np.ndarray
    dark: np.ndarray
    pixels: np.ndarray


@dataclass
class LightFit:
    """The measured point light (world frame, the scene file's).

    Attributes:
        position: (3,) metres.
        start: (3,) the scene file's position the fit started from, metres.
        intensity_albedo: (3,) the light's intensity times the board's albedo per channel, W/sr (a nuisance of
            the fit; divided by the board's albedo it estimates the intensity).
        dark_ratio: the chart's dark squares' albedo relative to the board's, as fitted.
        residual_rms: RMS of the fit's relative (log radiance) residuals over every pixel used.
        std_mm: (3,) the position's standard errors from the fit's residuals (pixel noise only; errors of the
            boards' measured poses come on top), millimetres.
        pixels: view pixels used, all boards.
        boards: boards used.
        per_board: per board: its measured centre and normal, pixels used and residual RMS.
    """

    position: np.ndarray
    start: np.ndarray
    intensity_albedo: np.ndarray
    dark_ratio: float
    residual_rms: float
    std_mm: np.ndarray
    pixels: int
    boards: int
    per_board: list = field(default_factory=list)

    def __post_init__(self) -> None:
        self.position = np.asarray(self.position, np.float64).reshape(3)
        self.start = np.asarray(self.start, np.float64).reshape(3)
        self.intensity_albedo = np.asarray(self.intensity_albedo, np.float64).reshape(3)
        self.std_mm = np.asarray(self.std_mm, np.float64).reshape(3)

    @property
    def shift_mm(self) -> float:
        """Distance from the scene file's position to the measured one, millimetres."""
        return float(1000 * np.linalg.norm(self.position - self.start))

    def to_json(self) -> dict:
        """The calibration file's ``light`` section."""
        return {"position_m": self.position.tolist(), "start_m": self.start.tolist(),
                "intensity_albedo": self.intensity_albedo.tolist(), "dark_ratio": float(self.dark_ratio),
                "residual_rms": float(self.residual_rms), "std_mm": self.std_mm.tolist(), "pixels": int(self.pixels),
                "boards": int(self.boards)}

    @classmethod
    def from_json(cls, data: dict) -> "LightFit":
        """From a validated ``light`` section (:class:`~lftransfer.calibration.calibration_file.LightEntry`);
        measurements a file lacks are NaN."""
        nan3 = [float("nan")] * 3

        def num(key):
            v = data.get(key)
            return float("nan") if v is None else float(v)

        return cls(position=data["position_m"], start=data.get("start_m") or nan3,
                   intensity_albedo=data.get("intensity_albedo") or nan3, dark_ratio=num("dark_ratio"),
                   residual_rms=num("residual_rms"), std_mm=data.get("std_mm") or nan3,
                   pixels=int(data.get("pixels") or 0), boards=int(data.get("boards") or 0))


# ---- the model ----------------------------------------------------------------------------------------------------
def _log_model(p: np.ndarray, points: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The point light's geometric factor on a Lambertian surface, in logarithms.

    Args:
        p: (3,) the light, metres.
        points: (N, 3) surface points, metres.
        normals: (N, 3) or (3,) their unit normals.

    Returns:
        log(n . (p - X) / |p - X|^3) (N,) (in m^-2; where n . (p - X) <= 0 it is taken at 1e-9 m), its gradient in
        p (N, 3), and n . (p - X) (N,) metres.
    """
    d = p[None, :] - points
    h = np.sum(d * normals, axis=1)
    r2 = np.einsum("ij,ij->i", d, d)
    safe = np.maximum(h, 1e-9)
    value = np.log(safe) - 1.5 * np.log(r2)
    grad = normals / safe[:, None] - 3.0 * d / r2[:, None]
    return value, grad, h


def fit_light(samples: list[LightSamples], start, *, dark_ratio: float = DARK_RATIO) -> LightFit:
    """The point light's position from boards' samples (module docstring, step 3).

    Args:
        samples: one :class:`LightSamples` per board (world frame).
        start: (3,) the position to start from (the scene file's), metres.
        dark_ratio: the chart's dark squares' relative albedo to start from (fitted).

    Returns:
        LightFit (``per_board`` holds each board's pixels and residual RMS).

    Raises:
        LightError: fewer than 2 boards, or a light that starts or ends behind a board.
    """
    if len(samples) < 2:
        raise LightError(f"point light: {len(samples)} board(s) to fit; one board fixes the light only weakly along "
                         "its normal (its distance trades against its intensity): at least 2 boards turned different "
                         "ways are needed")
    start = np.asarray(start, np.float64).reshape(3)
    pts = np.concatenate([s.points for s in samples])                         # (N, 3)
    nrm = np.concatenate([np.broadcast_to(s.normal, s.points.shape) for s in samples])
    rad = np.concatenate([s.radiance for s in samples]).astype(np.float64)    # (N, 3)
    dark = np.concatenate([s.dark for s in samples]).astype(np.float64)       # (N,)
    board = np.concatenate([np.full(len(s.points), i) for i, s in enumerate(samples)])
    n = len(pts)
    log_meas = np.log(rad)                                                    # (N, 3), radiance > 0 by selection

    def geometry(p):
        return _log_model(p, pts, nrm)

    def residuals(x):
        g, _, _ = geometry(x[:3])
        model = g[:, None] + x[None, 3:6] + (x[6] * dark)[:, None] - np.log(np.pi)
        return (model - log_meas).ravel()

    def jacobian(x):
        _, grad, _ = geometry(x[:3])
        J = np.zeros((n, 3, 7))
        J[:, :, :3] = grad[:, None, :]
        J[:, np.arange(3), 3 + np.arange(3)] = 1.0
        J[:, :, 6] = dark[:, None]
        return J.reshape(3 * n, 7)

    g0, _, h0 = geometry(start)
    if np.any(h0 <= 0):
        raise LightError("point light: the scene file's light stands behind a board's measured plane")
    # intensity x albedo per channel and the dark ratio: linear in the logarithms for the start's geometry
    log_k0 = np.median(log_meas - (g0 + np.log(dark_ratio) * dark - np.log(np.pi))[:, None], axis=0)
    x0 = np.concatenate([start, log_k0, [np.log(dark_ratio)]])
    scale = float(np.median(np.abs(residuals(x0) - np.median(residuals(x0))))) * 1.4826
    f_scale = max(3 * scale, 0.01)
    sol = least_squares(residuals, x0, jac=jacobian, loss="soft_l1", f_scale=f_scale, x_scale="jac",
                        xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=200)
    p = sol.x[:3]
    _, _, h = geometry(p)
    if np.any(h <= 0):
        raise LightError("point light: the fit puts the light behind a board; are the boards facing it?")
    res = residuals(sol.x).reshape(n, 3)
    rms = float(np.sqrt(np.mean(res ** 2)))
    J = jacobian(sol.x)
    try:
        cov = np.linalg.inv(J.T @ J) * (np.sum(res ** 2) / max(res.size - 7, 1))
        std = 1000 * np.sqrt(np.maximum(np.diag(cov)[:3], 0))
    except np.linalg.LinAlgError:
        std = np.full(3, np.inf)
    per_board = [{"pixels": int((board == i).sum()),
                  "residual_rms": float(np.sqrt(np.mean(res[board == i] ** 2)))} for i in range(len(samples))]
    return LightFit(position=p, start=start, intensity_albedo=np.exp(sol.x[3:6]), dark_ratio=float(np.exp(sol.x[6])),
                    residual_rms=rms, std_mm=std, pixels=n, boards=len(samples), per_board=per_board)


# ---- the boards' pixels ------------------------------------------------------------------------------------------
def board_samples(image: np.ndarray, view, to_world: np.ndarray, size: tuple[float, float],
                  chart: tuple[int, int, float] | None, *, max_pixels: int = 40_000,
                  margin_px: float = 2.0, min_margin_m: float = 0.002) -> LightSamples:
    """The view pixels on a board that the fit can use, and where they meet it.

    A pixel is used when its ray meets the board (``to_world``: the chart's frame from
    :func:`~lftransfer.calibration.pose.chart_pose`, the board centred on it) at least ``margin_px`` pixel
    footprints (and ``min_margin_m``) inside the board's edge and, on the chessboard, inside its square, and when
    its radiance is positive in every channel. Which squares are dark is read from the image (the darker half).

    Args:
        image: (H, W, 3) view camera radiance.
        view: ``ViewConfig`` (world frame).
        to_world: (4, 4) unit axes along the board's width and height, its normal (towards the camera), centre.
        size: (width, height) of the board, metres.
        chart: (columns, rows, square metres) printed on its centre, or None.
        max_pixels: at most about this many pixels (an even subset of the board's image).

    Returns:
        LightSamples.
    """
    h_img, w_img = image.shape[:2]
    ex, ey, normal, centre = (np.asarray(to_world[:3, i], np.float64) for i in range(4))
    half = np.asarray(size, np.float64) / 2
    corners = centre + np.array([[sx * half[0], sy * half[1]] for sx in (-1, 1) for sy in (-1, 1)]) @ np.stack([ex, ey])
    pc = project(view, corners)
    x0, y0 = np.clip(np.floor(pc.min(0)), 0, [w_img - 1, h_img - 1]).astype(int)
    x1, y1 = np.clip(np.ceil(pc.max(0)), 0, [w_img - 1, h_img - 1]).astype(int)
    stride = max(1, int(np.ceil(np.sqrt((x1 - x0 + 1) * (y1 - y0 + 1) / max_pixels))))
    ys, xs = np.mgrid[y0:y1 + 1:stride, x0:x1 + 1:stride]
    px = np.stack([xs.ravel(), ys.ravel()], 1).astype(np.float64)
    X = backproject(view, px, centre, normal)
    K, R, t = view_camera(view)
    eye = -R.T @ t
    dist = np.linalg.norm(X - eye, axis=1)
    slant = np.abs(((X - eye) / dist[:, None]) @ normal)
    footprint = dist / K[0, 0] / np.maximum(slant, 1e-3)                       # metres per pixel, longest way
    margin = np.maximum(margin_px * footprint, min_margin_m)
    u, v = (X - centre) @ ex, (X - centre) @ ey
    radiance = image[px[:, 1].astype(int), px[:, 0].astype(int)].astype(np.float64)     # (M, 3)
    keep = (np.abs(u) <= half[0] - margin) & (np.abs(v) <= half[1] - margin) & (slant > 0.05)
    dark = np.zeros(len(px), bool)
    if chart is not None:
        cols, rows, square = chart
        cw, ch = cols * square / 2, rows * square / 2
        on_chart = (np.abs(u) < cw + margin) & (np.abs(v) < ch + margin)
        fu, fv = (u + cw) / square, (v + ch) / square
        edge = np.minimum(np.abs(fu - np.round(fu)), np.abs(fv - np.round(fv))) * square   # to the nearest line
        inside = (np.abs(u) <= cw - margin) & (np.abs(v) <= ch - margin) & (edge >= margin)
        keep &= ~on_chart | inside
        parity = ((np.floor(fu) + np.floor(fv)) % 2).astype(int)
        grey = radiance.mean(1)
        both = keep & inside
        if np.any(both & (parity == 0)) and np.any(both & (parity == 1)):
            level = [np.median(grey[both & (parity == k)]) for k in (0, 1)]
            dark = inside & (parity == int(np.argmin(level)))
    keep &= np.all(np.isfinite(radiance) & (radiance > 0), axis=1)
    return LightSamples(points=X[keep], normal=normal, radiance=radiance[keep], dark=dark[keep], pixels=px[keep])


# ---- the poses ----------------------------------------------------------------------------------------------------
def _board_corners(centre: np.ndarray, normal: np.ndarray, size) -> np.ndarray:
    """(4, 3) corners of a board asked for at ``centre`` facing ``normal`` (the rig's
    :func:`~lftransfer.optics.geometry.rectangle_to_world` axes)."""
    m = rectangle_to_world(centre, normal, size)
    return centre + np.array([[sx, sy] for sx in (-1, 1) for sy in (-1, 1)], np.float64) @ m[:3, :2].T


def _chart_pose_cov(centre: np.ndarray, normal: np.ndarray, chart, view) -> np.ndarray:
    """(6, 6) covariance of a board's pose (translation, rotation vector about its centre) as its printed
    chessboard measures it: the inner corners' reprojection at :data:`DESIGN_CORNER_NOISE_PX` per coordinate,
    linearised (a chart far away or turned away from the camera is measured worse, mostly in depth)."""
    cols, rows, square = chart
    ex, ey, _ = plane_axes(normal)
    i, j = np.meshgrid(np.arange(1, cols) - cols / 2, np.arange(1, rows) - rows / 2)
    corners = centre + (i.reshape(-1, 1) * ex + j.reshape(-1, 1) * ey) * square      # (M, 3)
    step = 1e-6
    base = project(view, corners)
    J = np.zeros((2 * len(corners), 6))
    for k in range(6):
        e = np.eye(3)[k % 3] * step
        moved = corners + e if k < 3 else corners + np.cross(e, corners - centre)
        J[:, k] = ((project(view, moved) - base) / step).ravel()
    return DESIGN_CORNER_NOISE_PX ** 2 * np.linalg.inv(J.T @ J)


def _design_terms(centre: np.ndarray, normal: np.ndarray, size, chart, light: np.ndarray, view, grid: int = 16):
    """What one board adds to a linearised fit of (p, log intensity): information (4, 4) per unit pixel variance,
    the cross term (4, 6) with its pose error (translation, rotation vector about its centre) and that error's
    covariance (6, 6); over a grid of board points weighted by the view pixels they stand for."""
    ex, ey, n = plane_axes(normal)
    a = (np.arange(grid) + 0.5) / grid - 0.5
    s, t = np.meshgrid(a * size[0], a * size[1])
    X = centre + s.reshape(-1, 1) * ex + t.reshape(-1, 1) * ey                  # (G, 3)
    K, R, tv = view_camera(view)
    eye = -R.T @ tv
    to_eye = eye - X
    dist = np.linalg.norm(to_eye, axis=1)
    pixels = (size[0] * size[1] / grid ** 2) * (K[0, 0] / dist) ** 2 * np.abs((to_eye / dist[:, None]) @ n)
    _, grad, _ = _log_model(light, X, n)
    J = np.concatenate([grad, np.ones((len(X), 1))], 1)                        # (G, 4)
    # a board moved by tau and turned by w: X -> X + tau + w x (X - c), n -> n + w x n; the residual's change
    d = light - X
    h = d @ n
    B = np.zeros((len(X), 6))
    B[:, :3] = -grad
    arm = X - centre
    for i in range(3):
        w = np.eye(3)[i]
        B[:, 3 + i] = -np.einsum("ij,ij->i", grad, np.cross(w, arm)) + (d @ np.cross(w, n)) / h
    return (J * pixels[:, None]).T @ J, (J * pixels[:, None]).T @ B, _chart_pose_cov(centre, n, chart, view)


def _predicted_cov(terms: list) -> np.ndarray:
    """(3, 3) covariance of the light's position predicted for boards with these design terms: pixel noise
    (:data:`DESIGN_PIXEL_NOISE`) and each board's pose error as its chessboard measures it."""
    info = sum(t[0] for t in terms) / DESIGN_PIXEL_NOISE ** 2
    cov = np.linalg.inv(info)
    total = cov.copy()
    for _, cross, pose_cov in terms:
        G = cov @ cross / DESIGN_PIXEL_NOISE ** 2                               # (4, 6) parameters per pose error
        total += G @ pose_cov @ G.T
    return total[:3, :3]


def _chart_square_px(centre: np.ndarray, normal: np.ndarray, chart, view) -> float:
    """The narrowest of a board's printed chessboard squares in the view camera image, pixels.

    Each square of the chart (printed on the centre of a board asked for at ``centre`` facing ``normal``, along
    the rig's :func:`~lftransfer.optics.geometry.rectangle_to_world` axes) is drawn as a quadrilateral; its width
    across is its area over its longer side (the smaller of its heights, were it a parallelogram): how far apart
    two neighbouring chessboard lines run in the image, which the corner finder needs clear of its window
    (:data:`MIN_SQUARE_PX`). A chart seen obliquely by a coarse view camera may be whole in view and still too
    fine to find.
    """
    cols, rows, square = chart
    ex, ey, _ = plane_axes(normal)
    i, j = np.meshgrid(np.arange(cols + 1) - cols / 2, np.arange(rows + 1) - rows / 2)
    grid = project(view, centre + (i.reshape(-1, 1) * ex + j.reshape(-1, 1) * ey) * square).reshape(rows + 1,
                                                                                                    cols + 1, 2)
    a, b, d = grid[:-1, :-1], grid[:-1, 1:], grid[1:, :-1]
    u, v = b - a, d - a                                                      # each square's two sides
    area = np.abs(u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0])
    heights = area / np.maximum(np.maximum(np.linalg.norm(u, axis=-1), np.linalg.norm(v, axis=-1)), 1e-12)
    return float(heights.min())


def _candidate_poses(scene, light: np.ndarray, size, chart) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """The candidate board poses of :func:`light_board_poses` that pass its checks, in grid order.

    Returns:
        (centre (3,), unit normal (3,), :func:`_chart_square_px`) per candidate kept.
    """
    view = scene.view
    eye = np.asarray(view.origin, np.float64)
    w_img, h_img = view.resolution
    r = scene.rig
    half_w = 0.5 * r.cols * r.pitch_mm / 1000
    half_h = 0.5 * r.rows * r.pitch_mm / 1000
    chart_half = ((chart[0] + 2) * chart[2] / 2, (chart[1] + 2) * chart[2] / 2)
    angles = np.radians(GRID_TURNS_DEG)
    candidates = []
    for cx in np.linspace(-1, 1, GRID_XY) * GRID_SPAN * half_w:
        for cy in np.linspace(-1, 1, GRID_XY) * GRID_SPAN * half_h:
            for cz in GRID_DEPTHS_M:
                c = np.array([cx, cy, cz])
                to_light = light - c
                dist = np.linalg.norm(to_light)
                if dist < 0.05:
                    continue
                d = to_light / dist
                a1 = np.cross(d, [0.0, 0.0, 1.0])
                a1 = a1 / np.linalg.norm(a1) if np.linalg.norm(a1) > 1e-6 else np.array([1.0, 0.0, 0.0])
                a2 = np.cross(d, a1)
                for al in angles:
                    for be in angles:
                        n = Rotation.from_rotvec(al * a1 + be * a2).apply(d)
                        if n @ d < LIGHT_MIN_COS or n @ to_light < 0.05:
                            continue
                        if n @ (eye - c) / np.linalg.norm(eye - c) < VIEW_MIN_COS:
                            continue
                        if _board_corners(c, n, size)[:, 2].min() < CLEARANCE_M:
                            continue
                        pc = project(view, _board_corners(c, n, (2 * chart_half[0], 2 * chart_half[1])))
                        if not (np.all(pc[:, 0] >= 0.04 * w_img) and np.all(pc[:, 0] <= 0.96 * w_img)
                                and np.all(pc[:, 1] >= 0.04 * h_img) and np.all(pc[:, 1] <= 0.96 * h_img)):
                            continue
                        square_px = _chart_square_px(c, n, chart, view)
                        if square_px < MIN_SQUARE_PX:
                            continue
                        candidates.append((c, n, square_px))
    return candidates


def light_board_poses(scene, count: int = LIGHT_BOARDS, size=LIGHT_BOARD_SIZE, chart=LIGHT_CHART, *,
                      light: int = 0) -> list[Board]:
    """Where to ask for the boards that measure one point light (module docstring, step 1).

    Candidates: centres on a grid in front of the array (:data:`GRID_XY` per axis over :data:`GRID_SPAN` of its
    half extent, at :data:`GRID_DEPTHS_M`), normals turned from the direction to the scene file's light by
    :data:`GRID_TURNS_DEG` about two axes. A candidate is kept when the board faces the light (cosine at its
    centre >= :data:`LIGHT_MIN_COS`, its plane at least 5 cm from the light) and the view camera (cosine >=
    :data:`VIEW_MIN_COS`), its corners stay :data:`CLEARANCE_M` in front of the array's plane, its chessboard,
    one square wider each way, lies inside the view with 4 % to spare, and its squares, as the view camera sees
    them, are at least :data:`MIN_SQUARE_PX` pixels across (:func:`_chart_square_px`): turned far from the camera
    at a coarse view (``--quick``: a quarter of the pixels) the squares shrink to a few pixels across, where the
    chessboard's corners are found pixels off or not at all. ``count`` of them are chosen one by one, each the one
    that most lowers the predicted error of the light's position (:func:`_predicted_cov`'s trace).

    Args:
        scene: the synthetic part of the scene (its lights, view camera and rig file).
        count: boards to ask for (>= 2).
        size: (width, height) of the board, metres.
        chart: its printed chessboard.
        light: which of the scene's point lights (0-based).

    Returns:
        ``count`` :class:`~lftransfer.rig.requests.Board` requests with ``point_light=True`` (and, in a scene with
        several lights, ``light`` naming the one to switch on alone).

    Raises:
        LightError: the scene has no such point light, or fewer than ``count`` poses are seen well and lit.
    """
    if not 0 <= light < len(scene.lights):
        raise LightError(f"point light: the scene has {len(scene.lights)} point light(s) ([light]); "
                         f"there is no light {light} (0-based) to measure")
    if count < 2:
        raise ValueError(f"count: the light needs at least 2 boards, got {count}")
    index = light
    name = _light_name(scene, index)
    light = np.asarray(scene.lights[index].position, np.float64)
    view = scene.view
    candidates = [(c, n) for c, n, _ in _candidate_poses(scene, light, size, chart)]
    if len(candidates) < count:
        raise LightError(f"{name}: only {len(candidates)} board poses in front of the array face the light at "
                         f"{tuple(round(float(v), 3) for v in light)} m and the view camera and are seen well by it "
                         f"(the whole chessboard in view, its squares at least {MIN_SQUARE_PX:g} view pixels across); "
                         f"{count} are needed (move the light or the view camera, or use a finer view camera)")
    terms = [_design_terms(c, n, size, chart, light, view) for c, n in candidates]
    chosen: list[int] = []
    for _ in range(count):
        best, best_score = None, np.inf
        for i in range(len(candidates)):
            if i in chosen:
                continue
            try:
                score = float(np.trace(_predicted_cov([terms[j] for j in chosen] + [terms[i]])))
            except np.linalg.LinAlgError:
                continue
            if score < best_score:
                best, best_score = i, score
        if best is None:
            raise LightError(f"{name}: no set of board poses fixes the light's position")
        chosen.append(best)
    return [Board(centre=tuple(candidates[i][0].tolist()), normal=tuple(candidates[i][1].tolist()), size=tuple(size),
                  albedo=LIGHT_BOARD_ALBEDO, chart=tuple(chart), point_light=True,
                  light=None if len(scene.lights) == 1 else index) for i in chosen]


def _light_name(scene, light: int) -> str:
    """How messages name a light: "point light", or "point light 2" (1-based) in a scene with several."""
    return "point light" if len(scene.lights) == 1 else f"point light {light + 1}"


def count_light_messages(scene, boards: int = LIGHT_BOARDS) -> int:
    """Progress messages of :func:`calibrate_light` over every point light of the scene (0 without one)."""
    return len(scene.lights) * (boards + _MESSAGES_AFTER_BOARDS)


# ---- the step -----------------------------------------------------------------------------------------------------
def black_share(projector) -> np.ndarray:
    """(3,) the light a projector showing black sends, relative to what full white adds to it, per channel.

    A projector at codes n emits ``max_radiance * (black_level + C @ r(n))`` in every pixel it shows them
    (:class:`~lftransfer.lightfield.ProjectorModel`): black sends ``b``, full white ``b + C @ 1``. A uniform image
    lights a board through the lenslets with the same geometry at every code, so the black level's light on the
    board is the white photograph minus the black one times ``b / (C @ 1)``.
    """
    b = np.asarray(projector.black_level, np.float64)
    return b / projector.cross_talk_matrix.sum(axis=1)


def _light_board(rig: Rig, scene, asked, where: str, name: str, start: np.ndarray, intensity: tuple,
                 share: np.ndarray, spp: int):
    """One board of :func:`calibrate_light`: photographed lit by the point light with the projector black, then
    white too (the black level's light taken out), its pose from the chart, its lit pixels' samples checked for
    number and brightness. Returns (the board's samples, its diagnostics)."""
    eye = np.asarray(scene.view.origin, np.float64)
    black = rig.info.black()
    white = np.full_like(black, 2 ** rig.info.projector_bits - 1)
    rig.setup(asked)
    rig.project(black)
    lit = rig.capture_view(ViewCapture(quality=spp)).radiance
    rig.project(white)
    flood = rig.capture_view(ViewCapture(quality=max(1, spp // 4))).radiance   # scales a ~1 % correction
    rig.project(black)
    image = lit - (flood - lit) * share                  # the point light alone: the black level's light out
    try:
        m, chart_rms = chart_pose(lit, asked.chart, scene.view)
    except PoseError as exc:
        raise LightError(f"{where}: {exc}; is the point light on and the board in view, facing it?") from None
    if m[:3, 2] @ (eye - m[:3, 3]) < 0:                     # the normal towards the view camera (and the light)
        m[:3, 1:3] *= -1
    s = board_samples(image, scene.view, m, asked.size, asked.chart)
    if len(s.points) < MIN_PIXELS:
        raise LightError(f"{where}: only {len(s.points)} view camera pixels on the board are lit and usable "
                         f"(at least {MIN_PIXELS} needed); is the point light on and the board in view?")
    # as bright as the scene file's light would make it (its intensity, the board's albedo), within a factor
    g, _, _ = _log_model(start, s.points, s.normal)
    expected = np.exp(g)[:, None] * np.asarray(intensity) * LIGHT_BOARD_ALBEDO / np.pi \
        * np.where(s.dark, DARK_RATIO, 1.0)[:, None]
    brightness = float(np.median(s.radiance.sum(1) / np.maximum(expected.sum(1), 1e-30)))
    if not MIN_BRIGHTNESS <= brightness <= 1 / MIN_BRIGHTNESS:
        raise LightError(f"{where}: the board is {brightness:.3g} times as bright as the scene file's light "
                         f"(intensity {intensity} W/sr) would make it; is the {name} on, and the only light?")
    return s, {"asked_centre_m": list(asked.centre), "asked_normal": list(asked.normal),
               "centre_m": m[:3, 3].tolist(), "normal": m[:3, 2].tolist(), "chart_rms_px": chart_rms,
               "black_level_share": float(np.mean((flood - lit) * share) / max(float(np.mean(lit)), 1e-30))}


def calibrate_light(rig: Rig, model, scene, *, light: int = 0, boards: int = LIGHT_BOARDS, spp: int = LIGHT_SPP,
                    progress: Progress | None = None) -> tuple[LightFit, dict]:
    """Measure one point light's position through the rig (module docstring).

    In a scene with several point lights each is measured on its own: the boards are asked for with that light
    alone switched on (:class:`~lftransfer.rig.requests.Board` ``light``).

    Each board is photographed twice without moving it: lit by the point light with the projector black (the
    measurement), then with the projector full white too. The projector's black level (light at code 0, up to
    about 1 % of its range) also reaches a board that faces the array: the difference of the two photographs
    times :func:`black_share` (the calibrated black level over white) is that light, and it is taken out of the
    measurement.

    Args:
        rig: the rig; it is asked for ``boards`` :class:`~lftransfer.rig.requests.Board` set-ups with the point
            light on, and two view captures of each (projector black, then white).
        model: the calibrated ``RigModel`` (its projector's black level and cross-talk; nothing else is used).
        scene: the synthetic part of the scene (the scene file's lights, the view camera, the rig file).
        light: which of the scene's point lights (0-based).
        boards: poses photographed (>= 2).
        spp: view camera quality of the photographs.
        progress: called with a message per board and one for the fit.

    Returns:
        (LightFit, diagnostics: per board the asked and the measured pose, for reports).

    Raises:
        LightError: a board's chessboard not found, too little of a board in view, a board far darker or brighter
            than the scene file's light would make it (:data:`MIN_BRIGHTNESS`), or a fit that lands implausibly far
            (:data:`MAX_SHIFT_M`) from the scene file's position.
    """
    say = progress or (lambda msg: None)
    poses = light_board_poses(scene, boards, light=light)
    name = _light_name(scene, light)
    start = np.asarray(scene.lights[light].position, np.float64)
    intensity = tuple(scene.lights[light].intensity)
    share = black_share(model.projector).astype(np.float32)
    samples, per_board = [], []
    for i, asked in enumerate(poses, 1):
        where = f"{name}: board {i} of {len(poses)} at ({', '.join(f'{100 * v:+.0f}' for v in asked.centre)}) cm"
        say(f"{where}, lit by the {name} (projector black, then white)")
        sample, entry = _light_board(rig, scene, asked, where, name, start, intensity, share, spp)
        samples.append(sample)
        per_board.append(entry)
    say(f"{name}: fit of its position to the boards' shading")
    fit = fit_light(samples, start)
    for entry, fitted in zip(per_board, fit.per_board):
        entry.update(fitted)
    fit.per_board = per_board
    if fit.shift_mm > 1000 * MAX_SHIFT_M:
        raise LightError(f"{name}: the fit puts it {fit.shift_mm:.0f} mm from the scene file's position "
                         f"{tuple(round(float(v), 3) for v in start)} m (at most {1000 * MAX_SHIFT_M:.0f} mm expected; residual "
                         f"{100 * fit.residual_rms:.1f} %); is it where the scene file says, and the only light on?")
    return fit, {"boards": per_board}
