"""Camera intrinsics and lens distortion from chessboard photographs (Zhang's method, through OpenCV).

Used for users' own cameras and for the lenslet-intrinsics calibration of the light field transfer rig
(``lft calibrate intrinsics IMAGE... --pattern 9x6 --square-mm S --out intrinsics.json``).

Conventions are OpenCV's throughout:

* the pattern size is the number of *inner* corners ``(cols, rows)``, e.g. ``(9, 6)`` for a board of
  10 x 7 squares;
* pixel coordinates have their origin at the centre of the top-left pixel, x to the right, y down;
* the camera matrix is ``K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` in pixels;
* the distortion coefficients are ``(k1, k2, p1, p2, k3)`` (radial k1 k2 k3, tangential p1 p2), acting on
  normalised image coordinates (dimensionless).
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from lftransfer.imageio_utils import native_messages, write_text

__all__ = [
    "Intrinsics",
    "IntrinsicsError",
    "calibrate_intrinsics",
    "find_chessboard",
    "parse_pattern",
    "write_intrinsics_json",
]


class IntrinsicsError(ValueError):
    """An intrinsics calibration could not be done; the message names the offending file where there is one."""


@dataclass
class Intrinsics:
    """Result of a chessboard calibration.

    Attributes:
        image_size: ``(width, height)`` of the calibration images, pixels.
        camera_matrix: (3, 3) float64 camera matrix ``K``, pixels.
        dist_coeffs: (5,) float64 distortion coefficients ``k1 k2 p1 p2 k3`` (dimensionless).
        rms_px: overall reprojection RMS over all corners of all used views, pixels (as returned by
            ``cv2.calibrateCamera``: ``sqrt(sum |e|^2 / n_corners)``).
        per_view_rms_px: reprojection RMS of each used view, pixels, in the order of ``used``.
        used: the image paths (as given, ``str``) whose chessboard took part in the calibration.
        skipped: image path (``str``) -> reason, for views that were left out.
    """

    image_size: tuple[int, int]
    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    rms_px: float
    per_view_rms_px: list[float] = field(default_factory=list)
    used: list[str] = field(default_factory=list)
    skipped: dict[str, str] = field(default_factory=dict)

    def to_json(self) -> dict:
        """JSON-ready dict.

        Returns:
            ``{"rms_px": float, "camera_matrix": 3x3 nested lists, "dist_coeffs": list of 5,
            "image_size": [width, height], "per_view_rms_px": list, "used": list, "skipped": dict}``.
        """
        return {
            "rms_px": float(self.rms_px),
            "camera_matrix": [[float(v) for v in row] for row in np.asarray(self.camera_matrix).reshape(3, 3)],
            "dist_coeffs": [float(v) for v in np.asarray(self.dist_coeffs).ravel()[:5]],
            "image_size": [int(self.image_size[0]), int(self.image_size[1])],
            "per_view_rms_px": [float(v) for v in self.per_view_rms_px],
            "used": [str(u) for u in self.used],
            "skipped": {str(k): str(v) for k, v in self.skipped.items()},
        }


_PATTERN_RE = re.compile(r"^\s*(\d+)\s*[xX\u00d7*]\s*(\d+)\s*$")


def parse_pattern(text: str) -> tuple[int, int]:
    """Parse a chessboard pattern size such as ``"9x6"``.

    Args:
        text: ``"COLSxROWS"``: inner-corner counts, each at least 2 (``x``, ``X``, ``*`` or ``\u00d7``).

    Returns:
        ``(cols, rows)``, OpenCV's ``patternSize``.

    Raises:
        ValueError: the text is not of that form or a count is below 2.
    """
    m = _PATTERN_RE.match(str(text))
    if m is None:
        raise ValueError(
            f"invalid chessboard pattern {text!r}: expected inner-corner counts as COLSxROWS, e.g. '9x6' "
            "for a board of 10 x 7 squares"
        )
    cols, rows = int(m.group(1)), int(m.group(2))
    if cols < 2 or rows < 2:
        raise ValueError(f"invalid chessboard pattern {text!r}: each inner-corner count must be at least 2")
    return cols, rows


def _check_pattern(pattern) -> tuple[int, int]:
    try:
        cols, rows = (int(v) for v in pattern)
    except (TypeError, ValueError):
        raise ValueError(f"pattern must be (cols, rows) inner-corner counts, got {pattern!r}") from None
    if cols < 2 or rows < 2:
        raise ValueError(f"pattern inner-corner counts must each be at least 2, got {pattern!r}")
    return cols, rows


def _to_gray8(image: np.ndarray) -> np.ndarray:
    """Any 8/16-bit or float, grey/BGR/BGRA image -> (H, W) uint8 grey for the corner detectors.

    8-bit data is kept as is; other depths are stretched linearly between their 0.5 and 99.5 percentiles so that,
    e.g., 12-bit data in a 16-bit container is not left dim.
    """
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim == 3 and img.shape[2] in (3, 4):
        if img.dtype not in (np.uint8, np.uint16, np.float32):
            img = img.astype(np.float32)
        code = cv2.COLOR_BGR2GRAY if img.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
        img = cv2.cvtColor(np.ascontiguousarray(img), code)
    if img.ndim != 2:
        raise ValueError(f"expected a (H, W), (H, W, 3) or (H, W, 4) image, got shape {np.asarray(image).shape}")
    if img.dtype == np.uint8:
        return np.ascontiguousarray(img)
    if img.dtype == np.bool_:
        return img.astype(np.uint8) * 255
    f = img.astype(np.float64)
    finite = np.isfinite(f)
    if not finite.any():
        return np.zeros(img.shape, np.uint8)
    lo, hi = np.percentile(f[finite], [0.5, 99.5])
    if not hi > lo:
        return np.zeros(img.shape, np.uint8)
    f = np.where(finite, f, lo)
    return np.clip(np.round((f - lo) * (255.0 / (hi - lo))), 0, 255).astype(np.uint8)


def find_chessboard(image: np.ndarray, pattern: tuple[int, int]) -> np.ndarray | None:
    """Find the inner corners of a chessboard with sub-pixel accuracy.

    Tries ``cv2.findChessboardCornersSB`` (normal, then exhaustive search) and falls back to
    ``cv2.findChessboardCorners`` + ``cv2.cornerSubPix``.

    Args:
        image: (H, W), (H, W, 1), (H, W, 3) BGR or (H, W, 4) BGRA image; uint8, uint16 or float.
        pattern: inner-corner counts ``(cols, rows)`` (OpenCV's ``patternSize``).

    Returns:
        (cols * rows, 2) float32 corner positions in pixels, in OpenCV's row-major order (``cols`` corners per
        row), or ``None`` when the full pattern is not found.

    Raises:
        ValueError: bad image shape or pattern.
    """
    cols, rows = _check_pattern(pattern)
    gray = _to_gray8(image)
    n = cols * rows
    size = (cols, rows)

    sb_flags = cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_ACCURACY
    for flags in (sb_flags, sb_flags | cv2.CALIB_CB_EXHAUSTIVE):
        try:
            found, corners = cv2.findChessboardCornersSB(gray, size, flags=flags)
        except cv2.error:
            found, corners = False, None
        if found and corners is not None and corners.size == 2 * n:
            return np.ascontiguousarray(corners.reshape(n, 2), dtype=np.float32)

    classic = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    try:
        found, corners = cv2.findChessboardCorners(gray, size, flags=classic)
    except cv2.error:
        found, corners = False, None
    if not found or corners is None or corners.size != 2 * n:
        return None
    corners = corners.reshape(-1, 1, 2).astype(np.float32)
    # Search window about half the smallest corner spacing, bounded to [2, 11] px.
    pts = corners.reshape(rows, cols, 2)
    spacing = []
    if cols > 1:
        spacing.append(np.linalg.norm(np.diff(pts, axis=1), axis=2).min())
    if rows > 1:
        spacing.append(np.linalg.norm(np.diff(pts, axis=0), axis=2).min())
    win = int(np.clip(0.5 * min(spacing), 2, 11))
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-3)
    corners = cv2.cornerSubPix(gray, corners, (win, win), (-1, -1), criteria)
    return np.ascontiguousarray(corners.reshape(n, 2), dtype=np.float32)


def _load_image(path) -> np.ndarray:
    """Read an image file unchanged (any depth / channel count) with a clear error naming the file."""
    p = Path(path)
    if not p.exists():
        raise IntrinsicsError(f"cannot read calibration image {str(path)!r}: file not found")
    if not p.is_file():
        raise IntrinsicsError(f"cannot read calibration image {str(path)!r}: not a file")
    try:
        with native_messages() as said:
            img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
    except cv2.error as exc:  # pragma: no cover - depends on the OpenCV build
        raise IntrinsicsError(f"cannot read calibration image {str(path)!r}: {exc}") from None
    if img is None or img.size == 0:
        why = f": {'; '.join(said)}" if said else ""
        raise IntrinsicsError(
            f"cannot read calibration image {str(path)!r}: not a readable image file (corrupt or unsupported "
            f"format{why})"
        )
    return img


def _object_points(pattern: tuple[int, int], square_size_m: float) -> np.ndarray:
    """(cols * rows, 3) float32 board-plane corner positions in metres, ordered as OpenCV returns corners."""
    cols, rows = pattern
    obj = np.zeros((rows * cols, 3), np.float32)
    obj[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * np.float32(square_size_m)
    return obj


def _find_corners(paths: list, pattern: tuple[int, int]):
    """Each image's chessboard corners: the images' common size (w, h), the files used, those skipped with the
    reason, and the corners found, (N, 1, 2) per file used (the same file listed twice counts once).

    Raises:
        IntrinsicsError: an unreadable file, or images of different sizes.
    """
    cols, rows = pattern
    size: tuple[int, int] | None = None
    size_from = ""
    used: list[str] = []
    skipped: dict[str, str] = {}
    img_points: list[np.ndarray] = []
    for path in paths:
        name = str(path)
        img = _load_image(path)
        h, w = img.shape[:2]
        if size is None:
            size, size_from = (w, h), name
        elif (w, h) != size:
            raise IntrinsicsError(
                f"calibration images differ in size: {name!r} is {w}x{h} but {size_from!r} is {size[0]}x{size[1]}"
            )
        if name in used or name in skipped:  # the same file listed twice counts once
            continue
        try:
            corners = find_chessboard(img, (cols, rows))
        except ValueError as exc:
            skipped[name] = f"unsupported image layout: {exc}"
            continue
        if corners is None:
            skipped[name] = (
                f"chessboard pattern {cols}x{rows} (inner corners) not found in image {name!r}"
            )
            continue
        used.append(name)
        img_points.append(corners.reshape(-1, 1, 2))

    return size, used, skipped, img_points


def calibrate_intrinsics(paths: list, pattern: tuple[int, int], square_size_m: float) -> Intrinsics:
    """Calibrate a camera's intrinsics and distortion from chessboard photographs.

    Every image is read and checked for size first; views where the full pattern is not found are skipped and
    recorded with the reason. The 5-coefficient OpenCV model (k1 k2 p1 p2 k3) is fitted.

    Args:
        paths: image files (any format OpenCV reads; 8/16-bit, grey or colour), all of the same size.
        pattern: inner-corner counts ``(cols, rows)``.
        square_size_m: side of one chessboard square, metres (> 0). It scales only the extrinsics, not K.

    Returns:
        The calibration.

    Raises:
        IntrinsicsError: no images, an unreadable file, images of different sizes, fewer than 3 views with the
            pattern found, or the calibration failed.
        ValueError: bad pattern or square size.
    """
    cols, rows = _check_pattern(pattern)
    square = float(square_size_m)
    if not (math.isfinite(square) and square > 0):
        raise ValueError(f"square size must be a positive number of metres, got {square_size_m!r}")
    paths = list(paths)
    if not paths:
        raise IntrinsicsError("no calibration images given")

    obj = _object_points((cols, rows), square)
    size, used, skipped, img_points = _find_corners(paths, (cols, rows))
    if len(used) < 3:
        detail = "; ".join(f"{k}: {v}" for k, v in skipped.items()) or "none skipped"
        raise IntrinsicsError(
            f"only {len(used)} usable view(s) with the {cols}x{rows} inner-corner pattern out of {len(paths)} "
            f"image(s); at least 3 are needed (skipped: {detail})"
        )

    obj_points = [obj.reshape(-1, 1, 3)] * len(used)
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    try:
        rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(
            obj_points, img_points, size, None, None, flags=0, criteria=criteria
        )
    except cv2.error as exc:
        raise IntrinsicsError(f"calibration failed on {len(used)} views: {exc}") from None
    K = np.asarray(K, np.float64).reshape(3, 3)
    dist = np.zeros(5, np.float64) + np.asarray(dist, np.float64).ravel()[:5]
    if not (np.all(np.isfinite(K)) and np.all(np.isfinite(dist)) and math.isfinite(rms)):
        raise IntrinsicsError(f"calibration on {len(used)} views did not converge (non-finite result)")

    per_view = []
    for pts, rvec, tvec in zip(img_points, rvecs, tvecs):
        proj, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
        err = proj.reshape(-1, 2).astype(np.float64) - pts.reshape(-1, 2).astype(np.float64)
        per_view.append(float(np.sqrt(np.sum(err**2) / len(err))))

    return Intrinsics(
        image_size=(int(size[0]), int(size[1])),
        camera_matrix=K,
        dist_coeffs=dist,
        rms_px=float(rms),
        per_view_rms_px=per_view,
        used=used,
        skipped=skipped,
    )


def write_intrinsics_json(path, intr: Intrinsics) -> None:
    """Write ``intr.to_json()`` to ``path`` atomically (temporary file in the same folder, then ``os.replace``).

    Args:
        path: destination file; its folder is created if missing.
        intr: the calibration to write.
    """
    write_text(path, json.dumps(intr.to_json(), indent=2) + "\n")
