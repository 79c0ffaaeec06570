"""A camera or projector behind the lens array: device pixels <-> interface rays (k, d).

The device images the lenslets' common focal plane z = -f through a homography. A focal-plane point q behind
lenslet k has offset o = q - c_k; ideally (no distortion) it belongs to the ray d = normalize(-o_x, -o_y, f),
i.e. o = -f (u, v) with (u, v) = (d_x / d_z, d_y / d_z) (docs/architecture.md, "The interface").

Lens distortion is OpenCV's radial model, per lenslet, on normalised coordinates in the world orientation:
x_n = -(u, v), x_d = x_n (1 + k1 r^2 + k2 r^4) with r^2 = |x_n|^2, and o = f x_d.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lftransfer.optics.geometry import apply_homography
from lftransfer.optics.lens_array import LensArray

__all__ = ["LensletDevice"]

_NEWTON_ITERS = 60
_NEWTON_TOL = 1e-13


def _undistort_scale(rd2: np.ndarray, k1: np.ndarray, k2: np.ndarray) -> np.ndarray:
    """Scale s with x_n = s x_d, solving s (1 + k1 s^2 rd2 + k2 s^4 rd2^2) = 1 by Newton's method.

    Args:
        rd2: ``(N,)`` squared radius of the distorted normalised coordinates.
        k1, k2: ``(N,)`` radial coefficients.

    Returns:
        ``(N,) float64`` scale factors (1 where there is no distortion).
    """
    s = np.ones_like(rd2)
    a, b = k1 * rd2, k2 * rd2 * rd2
    for _ in range(_NEWTON_ITERS):
        s2 = s * s
        g = s * (1.0 + a * s2 + b * s2 * s2) - 1.0
        dg = 1.0 + 3.0 * a * s2 + 5.0 * b * s2 * s2
        step = g / dg
        s = s - step
        if not np.any(np.abs(step) > _NEWTON_TOL):
            break
    return s


def as_rays(k, d) -> tuple[np.ndarray, np.ndarray]:
    """Validate a batch of interface rays.

    Args:
        k: ``(N,)`` integer lenslet indices.
        d: ``(N, 3)`` directions.

    Returns:
        ``k`` as an integer array and ``d`` as float64.
    """
    k = np.asarray(k)
    d = np.asarray(d, dtype=np.float64)
    if k.ndim != 1 or d.shape != (len(k), 3):
        raise ValueError(f"k must have shape (N,) and d shape (N, 3), got {k.shape} and {d.shape}")
    if not np.issubdtype(k.dtype, np.integer):
        raise ValueError(f"k must be an integer array, got dtype {k.dtype}")
    return k, d


@dataclass(frozen=True, eq=False)
class LensletDevice:
    """A camera or projector behind the array that images the lenslets' focal plane (z = -f).

    Attributes:
        width: Image width, pixels.
        height: Image height, pixels.
        homography: ``(3, 3) float64``: focal-plane point (x, y, 1), metres in world x, y, -> pixel
            (col, row, 1); pixel (0, 0) is the centre of the top-left pixel.
        distortion: ``(K, 2) float64`` per-lenslet radial coefficients (k1, k2), OpenCV convention.
    """

    width: int
    height: int
    homography: np.ndarray
    distortion: np.ndarray

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"{name} must be a positive number of pixels, got {value!r}")
            object.__setattr__(self, name, int(value))
        H = np.array(self.homography, dtype=np.float64)
        if H.shape != (3, 3) or not np.all(np.isfinite(H)):
            raise ValueError(f"homography must be a finite (3, 3) matrix, got shape {H.shape}")
        if abs(np.linalg.det(H)) < 1e-300:
            raise ValueError("homography must be invertible")
        H.setflags(write=False)
        object.__setattr__(self, "homography", H)
        D = np.array(self.distortion, dtype=np.float64)
        if D.ndim != 2 or D.shape[1] != 2 or not np.all(np.isfinite(D)):
            raise ValueError(f"distortion must be a finite (K, 2) array of (k1, k2), got shape {D.shape}")
        D.setflags(write=False)
        object.__setattr__(self, "distortion", D)
        Hinv = np.linalg.inv(H)
        Hinv.setflags(write=False)
        object.__setattr__(self, "_Hinv", Hinv)

    @classmethod
    def fronto_parallel(cls, array: LensArray, width: int, height: int, margin: float = 0.02,
                        distortion: np.ndarray | None = None) -> "LensletDevice":
        """A device looking straight at the focal plane, the array filling the image.

        A uniform scale (square pixels) maps ``array.extent()``, grown by ``margin`` times its size on every
        side, into the image, centred; world +y maps to decreasing row (image up).

        Args:
            array: The lens array.
            width: Image width, pixels.
            height: Image height, pixels.
            margin: Border around the array as a fraction of its size (>= 0).
            distortion: ``(K, 2)`` radial (k1, k2) per lenslet; zeros when None.

        Returns:
            The device.
        """
        if margin < 0:
            raise ValueError(f"margin must be >= 0, got {margin}")
        xmin, xmax, ymin, ymax = array.extent()
        w, h = xmax - xmin, ymax - ymin
        span_x, span_y = w * (1.0 + 2.0 * margin), h * (1.0 + 2.0 * margin)
        scale = min(width / span_x, height / span_y)  # pixels per metre
        xc, yc = 0.5 * (xmin + xmax), 0.5 * (ymin + ymax)
        cx, cy = 0.5 * (width - 1), 0.5 * (height - 1)
        H = np.array([[scale, 0.0, cx - scale * xc],
                      [0.0, -scale, cy + scale * yc],
                      [0.0, 0.0, 1.0]])
        if distortion is None:
            distortion = np.zeros((array.K, 2))
        return cls(width=width, height=height, homography=H, distortion=distortion)

    def _check(self, array: LensArray) -> None:
        if self.distortion.shape != (array.K, 2):
            raise ValueError(f"distortion has shape {self.distortion.shape}, expected ({array.K}, 2) for this array")

    def pixel_to_ray(self, array: LensArray, px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Interface rays of device pixels.

        Args:
            array: The lens array in front of the device.
            px: ``(N, 2)`` pixel coordinates (col, row), pixel (0, 0) the centre of the top-left pixel.

        Returns:
            ``k``: ``(N,) int64`` lenslet index, -1 where the pixel sees no lenslet;
            ``d``: ``(N, 3) float64`` unit directions (d_z > 0); NaN where ``k == -1``.
        """
        self._check(array)
        px = np.asarray(px, dtype=np.float64)
        if px.ndim != 2 or px.shape[1] != 2:
            raise ValueError(f"px must have shape (N, 2), got {px.shape}")
        q = apply_homography(self._Hinv, px)
        k = array.lenslet_at(q)
        valid = k >= 0
        kv = k[valid]
        xd = (q[valid] - array.centres[kv]) / array.focal_length
        rd2 = np.sum(xd * xd, axis=1)
        s = _undistort_scale(rd2, self.distortion[kv, 0], self.distortion[kv, 1])
        xn = xd * s[:, None]
        d = np.full((len(px), 3), np.nan)
        dv = np.concatenate([-xn, np.ones((len(xn), 1))], axis=1)
        d[valid] = dv / np.linalg.norm(dv, axis=1, keepdims=True)
        return k, d

    def ray_to_pixel(self, array: LensArray, k: np.ndarray, d: np.ndarray) -> np.ndarray:
        """Device pixels of interface rays (the exact inverse of :meth:`pixel_to_ray`).

        Args:
            array: The lens array in front of the device.
            k: ``(N,)`` integer lenslet indices.
            d: ``(N, 3)`` directions with d_z > 0 (need not be unit).

        Returns:
            ``(N, 2) float64`` pixel coordinates (col, row); NaN where ``k`` is out of range or d_z <= 0.
        """
        self._check(array)
        k, d = as_rays(k, d)
        valid = (k >= 0) & (k < array.K) & (d[:, 2] > 0)
        kv = k[valid].astype(np.int64)
        dv = d[valid]
        xn = -dv[:, :2] / dv[:, 2:3]
        r2 = np.sum(xn * xn, axis=1)
        k1, k2 = self.distortion[kv, 0], self.distortion[kv, 1]
        xd = xn * (1.0 + k1 * r2 + k2 * r2 * r2)[:, None]
        q = array.centres[kv] + array.focal_length * xd
        out = np.full((len(k), 2), np.nan)
        out[valid] = apply_homography(self.homography, q)
        return out
