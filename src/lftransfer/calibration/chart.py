"""The printed chessboard on a calibration board: where the board stands, from the view camera's image.

Every board of the calibration carries the same printed chart (:data:`CHART`); the view camera measures the board's
pose from it (:func:`chart_pose`, metric, ``cv2.solvePnP``). The corners are found, refined one by one with a window
that suits the squares' size in the image, and, on a translucent screen at a coarse view, the whole chart is aligned
with its image (:func:`aligned_corners`). docs/calibration.md, step 5, says what each part measured.
"""

from __future__ import annotations

import cv2
import numpy as np

from lftransfer.optics.geometry import view_camera

__all__ = ["ALIGN_MAX_SPACING_PX", "CHART", "CHART_GRID_MAX_PX", "CORNER_WINDOW_MIN_PX", "CORNER_WINDOW_PX",
           "PoseError", "aligned_corners", "board_plane", "chart_pose", "corner_spacing", "corner_window"]


class PoseError(ValueError):
    """The board's corners could not be found or the pose could not be solved."""


CHART = (7, 5, 0.022)     # the chessboard printed on the calibration boards: columns, rows of squares, square metres
CORNER_WINDOW_PX = 5      # the largest half size of the corners' refinement window (cv2.cornerSubPix), view pixels
CORNER_WINDOW_MIN_PX = 3  # ... and the smallest
CORNER_CLEARANCE_PX = 4   # the window stops this far short of the neighbouring corners (:func:`corner_window`)


def corner_window(corners: np.ndarray, pattern: tuple[int, int]) -> int:
    """The half size of the corners' refinement window for a chessboard whose corners were found at ``corners``.

    ``cv2.cornerSubPix`` refines a corner from the image's gradients within the window; where the window reaches
    the neighbouring corners' lines (blurred over a pixel or two) they pull it off. So the window is the corners'
    smallest spacing in the image less :data:`CORNER_CLEARANCE_PX`, between :data:`CORNER_WINDOW_MIN_PX` and
    :data:`CORNER_WINDOW_PX`. Measured on 112 simulated boards of the built-in scenes at quarter resolution (squares
    6.2 to 11.2 pixels apart): with a window of 5 every board whose corners were 8.1 pixels apart or less was
    measured 0.3 to 0.6 degree askew (0.34 degree RMS over the point light's boards, which put the corner's point
    light 1 mm off); with this window 0.07 degree, and the boards with wider squares as before.

    Args:
        corners: (N, 2) the inner corners as ``cv2.findChessboardCorners`` orders them (row by row).
        pattern: (per row, rows) of inner corners.
    """
    return int(np.clip(np.floor(corner_spacing(corners, pattern)) - CORNER_CLEARANCE_PX, CORNER_WINDOW_MIN_PX,
                       CORNER_WINDOW_PX))


def corner_spacing(corners: np.ndarray, pattern: tuple[int, int]) -> float:
    """The smallest distance between neighbouring corners of a chessboard, pixels (``corners``: (N, 2) in
    OpenCV's order, ``pattern``: (per row, rows) of inner corners)."""
    grid = np.asarray(corners, np.float64).reshape(pattern[1], pattern[0], 2)
    return float(min(np.linalg.norm(np.diff(grid, axis=1), axis=2).min(),
                     np.linalg.norm(np.diff(grid, axis=0), axis=2).min()))


def chart_pose(image: np.ndarray, chart: tuple[int, int, float], view, *, window: int | None = None,
               screen: bool = False) -> tuple[np.ndarray, float]:
    """Where a board stands in the world, from the chessboard printed on it (``cv2.solvePnP``, metric).

    The corners are found (``cv2.findChessboardCorners``) and refined one by one (``cv2.cornerSubPix``); on a
    translucent ``screen`` whose squares are under :data:`ALIGN_MAX_SPACING_PX` apart the whole chart is then
    aligned with the image (:func:`aligned_corners`).

    Args:
        image: (H, W, 3) view camera image (linear radiance) of the lit board.
        chart: (columns, rows, square size in metres) of the printed chessboard's squares.
        view: ``ViewConfig``.
        window: the corners' refinement window, half size in pixels (default: :func:`corner_window`).
        screen: the chart is seen through a translucent screen (:func:`board_pattern`'s ``translucent``).

    Returns:
        (4, 4) the chart's frame in the world (columns: unit axes along its columns and rows, its normal, and its
        centre), and the chart's reprojection RMS in pixels. An odd-by-odd chart looks the same turned half-way or
        mirrored, so the axes' signs are those of OpenCV's corner order.
    """
    cols, rows, square = chart
    grey = image.mean(axis=2)
    grey8 = np.clip(255 * grey / max(np.percentile(grey, 99.5), 1e-12), 0, 255).astype(np.uint8)
    pattern = (cols - 1, rows - 1)
    obj = _inner_corners(chart)
    corners = _found_corners(grey8, obj[:, :2], pattern)
    if corners is None:
        raise PoseError(f"the printed {cols} x {rows} chessboard was not found in the view camera image")
    corners = _refined_corners(grey8, corners, obj[:, :2], pattern, window)
    if screen and corner_spacing(corners, pattern) < ALIGN_MAX_SPACING_PX:
        corners = aligned_corners(grey, chart, corners)
    K, R, t = view_camera(view)
    ok, rvec, tvec = cv2.solvePnP(obj, corners.astype(np.float64), K, None)
    if not ok:
        raise PoseError("solvePnP failed on the printed chessboard")
    proj, _ = cv2.projectPoints(obj, rvec, tvec, K, None)
    rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - corners) ** 2, axis=1))))
    m = np.eye(4)
    m[:3, :3] = R.T @ cv2.Rodrigues(rvec)[0]
    m[:3, 3] = R.T @ (tvec.ravel() - t)
    return m, rms


CORNER_MAX_RESIDUAL_PX = 0.6   # refined corners farther than this (RMS) from the homography that fits them best are
                               # refined again with a wider window


CHART_GRID_MAX_PX = 1.0   # corners found farther than this (RMS) from one plane's image are not the chart's grid


def _found_corners(grey8: np.ndarray, obj: np.ndarray, pattern: tuple[int, int]) -> np.ndarray | None:
    """(N, 2) the chart's inner corners as found in the (H, W) 8-bit image, OpenCV's order, or None.

    ``cv2.findChessboardCorners`` first; where it finds nothing, or corners that do not lie on one plane's image
    (their homography's residual over :data:`CHART_GRID_MAX_PX`: at the paper's resolution it ordered two of the
    corner scene's four point light boards wrongly, 4 and 7 pixels off, which put the light 8 mm off), the
    sector-based finder (``cv2.findChessboardCornersSB``, exhaustive and accurate)."""
    ok, corners = cv2.findChessboardCorners(grey8, pattern, flags=cv2.CALIB_CB_ADAPTIVE_THRESH)
    if ok and _grid_residual(obj, corners.reshape(-1, 2)) <= CHART_GRID_MAX_PX:
        return corners.reshape(-1, 2)
    found, other = cv2.findChessboardCornersSB(grey8, pattern,
                                               flags=cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY)
    if found and _grid_residual(obj, other.reshape(-1, 2)) <= CHART_GRID_MAX_PX:
        return other.reshape(-1, 2)
    return corners.reshape(-1, 2) if ok else None


def _grid_residual(obj: np.ndarray, corners: np.ndarray) -> float:
    """RMS distance (pixels) of (N, 2) ``corners`` from the image of the (N, 2) chart points ``obj`` under the
    homography that fits them best (inf where none does)."""
    H, _ = cv2.findHomography(obj, corners)
    if H is None:
        return float("inf")
    return float(np.sqrt(np.mean(np.sum((cv2.perspectiveTransform(obj[None], H)[0] - corners) ** 2, axis=1))))


def _refined_corners(grey8: np.ndarray, found: np.ndarray, obj: np.ndarray, pattern: tuple[int, int],
                     window: int | None) -> np.ndarray:
    """(N, 2) the corners ``found`` (pixels) refined by ``cv2.cornerSubPix``, with ``window`` or
    :func:`corner_window`'s; where the refined corners do not lie on one plane's image (their homography's
    residual over :data:`CORNER_MAX_RESIDUAL_PX`: one corner pulled away, as a window of 3 pixels once pulled one of
    a chart whose squares were 8 pixels apart), again with the next wider window, up to :data:`CORNER_WINDOW_PX`."""
    first = corner_window(found, pattern) if window is None else int(window)
    best, best_residual = found, np.inf
    for half in range(first, max(first, CORNER_WINDOW_PX) + 1):
        refined = cv2.cornerSubPix(grey8.astype(np.float32), found.astype(np.float32).reshape(-1, 1, 2),
                                   (half, half), (-1, -1),
                                   (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)).reshape(-1, 2)
        residual = _grid_residual(obj, refined)
        if residual < best_residual:
            best, best_residual = refined, residual
        if residual <= CORNER_MAX_RESIDUAL_PX or window is not None:
            break
    return best


def _inner_corners(chart: tuple[int, int, float]) -> np.ndarray:
    """(N, 3) the chart's inner corners in its own frame (metres, centred, z = 0), in OpenCV's order."""
    cols, rows, square = chart
    i, j = np.meshgrid(np.arange(cols - 1), np.arange(rows - 1))
    return np.stack([i.ravel() - (cols - 2) / 2, j.ravel() - (rows - 2) / 2, np.zeros(i.size)], 1) * square


ALIGN_TEXEL_M = 0.0005    # the drawn chart's texel for :func:`aligned_corners`, metres (at most half a view pixel)
ALIGN_EDGE_PX = 1.5       # the board's shading is fitted on pixels at least this far from the squares' edges
ALIGN_ROUNDS = 2          # shading fitted, chart aligned; twice
ALIGN_MAX_SPACING_PX = 20.0   # a screen's chart is aligned as a whole where its corners are closer than this: at
                              # quarter resolution (corners 8 to 11 pixels apart) it measured the screens' tilt
                              # to 0.05 degree RMS against 0.25 from the corners; at the paper's (about 35 pixels)
                              # the corners alone measured four of the corner's side screens to 0.03 degree,
                              # the alignment to 0.13 (0.26 at worst, 0.5 to 0.8 mm off in depth; not explained;
                              # its front's calibration did better aligned: docs/interfaces.md)


def aligned_corners(grey: np.ndarray, chart: tuple[int, int, float], corners: np.ndarray) -> np.ndarray:
    """The chart's inner corners where the whole chart, drawn, aligns with its image.

    Each corner refined on its own sees a few pixels round it. Here every pixel of the chart (and half a square of
    the board round it) counts: the board's shading (a quadratic in the image's coordinates, fitted to the image
    over the printed albedo on pixels clear of the squares' edges) is divided out, and the homography that aligns a
    drawn chart (albedo 1 and 1/4) with the result is solved by enhanced correlation (``cv2.findTransformECC``),
    starting from ``corners``; twice, the second fit of the shading using the first alignment.

    On a translucent screen seen from behind (where it is used: :func:`chart_pose`'s ``screen``) this measured
    each of 60 simulated pose screens of the corner and the enclosure at quarter resolution to 0.10 mm along its
    normal and 0.05 degree in tilt (RMS; 0.12 degree at worst), against 0.4 mm and 0.25 degree from the corners
    alone. On opaque boards it gained nothing and, twice in 52, tilted one by half a degree or more; at the paper's
    resolution the corners alone measured the corner's side screens better (:data:`ALIGN_MAX_SPACING_PX`).

    Args:
        grey: (H, W) the image's brightness (linear).
        chart: (columns, rows, square size in metres).
        corners: (N, 2) the inner corners as found (OpenCV's order), pixels.

    Returns:
        (N, 2) the corners of the aligned chart, pixels; ``corners`` itself when the alignment does not converge.
    """
    cols, rows, square = chart
    obj = _inner_corners(chart)[:, :2]
    H, _ = cv2.findHomography(obj, corners)
    if H is None:
        return corners
    grey = np.asarray(grey, np.float64) / max(float(np.percentile(grey, 99.5)), 1e-12)
    ys, xs = np.mgrid[0:grey.shape[0], 0:grey.shape[1]]
    pixels = np.stack([xs.ravel(), ys.ravel()], 1).astype(np.float64)
    step = cv2.perspectiveTransform(np.array([[[0.0, 0.0], [square, 0.0], [0.0, square]]]), H)[0]
    px_per_m = min(np.linalg.norm(step[1] - step[0]), np.linalg.norm(step[2] - step[0])) / square
    texel = min(ALIGN_TEXEL_M, 0.5 / px_per_m)
    half = np.array([cols + 1.0, rows + 1.0]) * square / 2                 # the chart and half a square round it
    size = np.round(2 * half / texel).astype(int)
    to_chart = np.array([[texel, 0.0, texel / 2 - half[0]], [0.0, texel, texel / 2 - half[1]], [0.0, 0.0, 1.0]])
    u, v = np.meshgrid((np.arange(size[0]) + 0.5) * texel - half[0], (np.arange(size[1]) + 0.5) * texel - half[1])
    seen = cv2.perspectiveTransform(pixels[None], np.linalg.inv(H))[0]
    dark_first = _chart_albedo(seen, chart, True)
    inside = np.all(np.abs(seen) < [cols * square / 2, rows * square / 2], axis=1)
    parity = grey.ravel()[inside & (dark_first < 1)].mean() < grey.ravel()[inside & (dark_first == 1)].mean()
    drawn = _chart_albedo(np.stack([u, v], -1).reshape(-1, 2), chart, parity).reshape(size[1], size[0])
    for round_ in range(ALIGN_ROUNDS):
        if round_:                                       # where the previous round's alignment puts each pixel
            seen = cv2.perspectiveTransform(pixels[None], np.linalg.inv(H))[0]
        edge = np.abs((seen / square + [cols / 2, rows / 2] + 0.5) % 1.0 - 0.5).min(axis=1) * square * px_per_m
        use = np.all(np.abs(seen) < half, axis=1) & (edge > ALIGN_EDGE_PX)
        if use.sum() < 50:
            return corners
        centre = pixels[use].mean(axis=0)
        shading = _quadratic(pixels - centre, np.linalg.lstsq(_quadratic(pixels[use] - centre, None),
                                                              grey.ravel()[use] / _chart_albedo(seen[use], chart,
                                                                                                parity),
                                                              rcond=None)[0])
        flat = (grey / np.maximum(shading.reshape(grey.shape), 1e-6)).astype(np.float32)
        warp = (H @ to_chart).astype(np.float32)
        try:
            _, warp = cv2.findTransformECC(drawn.astype(np.float32), flat, warp / warp[2, 2],
                                           cv2.MOTION_HOMOGRAPHY,
                                           (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 200, 1e-8), None, 1)
        except cv2.error:
            return corners
        H = warp.astype(np.float64) @ np.linalg.inv(to_chart)
    return cv2.perspectiveTransform(obj[None], H)[0]


def _chart_albedo(points: np.ndarray, chart: tuple[int, int, float], parity: bool) -> np.ndarray:
    """(N,) the printed albedo, relative to the board's, at (N, 2) chart-frame points (metres): 1/4 on the dark
    squares (those whose indices' sum is even when ``parity``), 1 elsewhere."""
    cols, rows, square = chart
    i = np.floor(points[:, 0] / square + cols / 2)
    j = np.floor(points[:, 1] / square + rows / 2)
    inside = (i >= 0) & (i < cols) & (j >= 0) & (j < rows)
    return np.where(inside & (((i + j) % 2 == 0) == parity), 0.25, 1.0)


def _quadratic(xy: np.ndarray, coefficients: np.ndarray | None) -> np.ndarray:
    """The terms (N, 6) of a quadratic in (N, 2) pixel offsets (per 100 pixels), or its values (N,) with
    ``coefficients``."""
    x, y = xy[:, 0] / 100.0, xy[:, 1] / 100.0
    terms = np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], 1)
    return terms if coefficients is None else terms @ coefficients


def board_plane(image: np.ndarray, chart: tuple[int, int, float], view, *,
                screen: bool = False) -> tuple[np.ndarray, np.ndarray, float]:
    """The board's plane in the world from the chessboard printed on it (:func:`chart_pose`; ``screen``: seen
    through a translucent screen).

    Returns:
        point (3,) and unit normal (3,) of the plane in the world, and the chart's reprojection RMS in pixels.
    """
    m, rms = chart_pose(image, chart, view, screen=screen)
    return m[:3, 3], m[:3, 2], rms
