"""Projector-to-camera mapping by structured light (paper, section 4.2).

With a diffuser at the lenslets' focal plane, the LF camera sees the projector's image directly: both devices
image the same plane, so camera and projector pixels are related by one homography. Binary Gray-code patterns
(each with its inverse, for a threshold that needs no knowledge of the responses) give every camera pixel the
projector column and row it sees; a least-squares homography over all of them averages the one-pixel
quantisation of the codes down to a small fraction of a pixel.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from lftransfer.optics.geometry import apply_homography


def _bits(n: int) -> int:
    return max(1, int(np.ceil(np.log2(n))))


def gray_code_patterns(width: int, height: int) -> list[np.ndarray]:
    """Projector images that encode each pixel's column and row in Gray code, each followed by its inverse.

    Args:
        width, height: projector size in pixels.

    Returns:
        list of 2 * (ceil(log2 width) + ceil(log2 height)) images, (height, width) uint8 in {0, 255}:
        column bits (most significant first), then row bits.
    """
    out = []
    for size, axis in ((width, 1), (height, 0)):
        index = np.arange(size)
        gray = index ^ (index >> 1)
        for b in reversed(range(_bits(size))):
            line = ((gray >> b) & 1).astype(np.uint8) * 255
            img = np.broadcast_to(line[None, :] if axis == 1 else line[:, None], (height, width))
            out += [np.ascontiguousarray(img), np.ascontiguousarray(255 - img)]
    return out


def decode_gray_code(captures: list[np.ndarray], width: int, height: int,
                     min_contrast: float = 0.02) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Projector column and row seen by every camera pixel.

    Args:
        captures: camera images (H, W) float, one per pattern of :func:`gray_code_patterns`, same order.
        width, height: projector size.
        min_contrast: smallest |pattern - inverse| (in the captures' units) for a bit to count as seen.

    Returns:
        column (H, W) int, row (H, W) int, valid (H, W) bool (every bit seen, codes inside the projector).
    """
    nx, ny = _bits(width), _bits(height)
    if len(captures) != 2 * (nx + ny):
        raise ValueError(f"expected {2 * (nx + ny)} captures for a {width} x {height} projector, got {len(captures)}")
    valid = np.ones(captures[0].shape, bool)
    codes = []
    for start, n in ((0, nx), (2 * nx, ny)):
        gray = np.zeros(captures[0].shape, np.int64)
        for i in range(n):
            pos, neg = captures[start + 2 * i], captures[start + 2 * i + 1]
            valid &= np.abs(pos - neg) >= min_contrast
            gray = (gray << 1) | (pos > neg)
        binary = gray.copy()
        shift = gray >> 1
        while np.any(shift):
            binary ^= shift
            shift >>= 1
        codes.append(binary)
    col, row = codes
    valid &= (col < width) & (row < height)
    return col, row, valid


@dataclass
class ProjectorCameraFit:
    """Homography from LF camera pixels to projector pixels.

    Attributes:
        homography: (3, 3) camera pixel (x, y, 1) -> projector pixel.
        rms_px: RMS residual of the per-pixel codes against the fit, projector pixels (includes the codes'
            own quantisation, about 0.41 px).
        pixels: number of camera pixels used.
    """

    homography: np.ndarray
    rms_px: float
    pixels: int

    def camera_to_projector(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) camera pixels -> (N, 2) projector pixels."""
        return apply_homography(self.homography, xy)


def fit_projector_camera(column: np.ndarray, row: np.ndarray, valid: np.ndarray,
                         max_points: int = 200_000, seed: int = 0) -> ProjectorCameraFit:
    """Least-squares homography (after RANSAC against stray codes) from decoded camera pixels.

    Args:
        column, row, valid: output of :func:`decode_gray_code`.
        max_points: correspondences used at most (a random subset).
        seed: subset seed.

    Returns:
        ProjectorCameraFit.
    """
    ys, xs = np.nonzero(valid)
    if len(xs) < 100:
        raise ValueError(f"only {len(xs)} camera pixels decoded a projector code: is the pattern visible?")
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(xs), min(max_points, len(xs)), replace=False)
    cam = np.stack([xs[pick], ys[pick]], 1).astype(np.float64)
    prj = np.stack([column[ys[pick], xs[pick]], row[ys[pick], xs[pick]]], 1).astype(np.float64)
    _, inliers = cv2.findHomography(cam, prj, cv2.RANSAC, 2.0)
    keep = inliers.ravel().astype(bool)
    H, _ = cv2.findHomography(cam[keep], prj[keep], 0)     # least squares on the inliers
    fit = ProjectorCameraFit(homography=H / H[2, 2], rms_px=0.0, pixels=int(keep.sum()))
    residual = fit.camera_to_projector(cam[keep]) - prj[keep]
    fit.rms_px = float(np.sqrt(np.mean(np.sum(residual ** 2, axis=1))))
    return fit
