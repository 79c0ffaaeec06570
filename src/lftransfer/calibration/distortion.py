"""Lenslet distortion from a tilted collimator (paper, section 4.2: the lenslets' intrinsics).

A collimated beam arriving from direction d focuses, behind every lenslet, at the focal-plane offset
``o = f x_d`` with ``x_d = x_n (1 + k1 r^2 + k2 r^4)``, ``x_n = -(d_x, d_y) / d_z`` (OpenCV's radial model,
:mod:`lftransfer.optics.device`). Tilting the collimator on its mount through a grid of known angles and
locating every lenslet's spot (the same sub-pixel detector as the lenslet centres) gives each lenslet a set
of (x_n, x_d) pairs: the view through each lenslet of a target at infinity with known directions, which is
Zhang's planar calibration with the plane at infinity. The focal length and principal point of each lenslet are
fixed by the lattice (the centres' homography and the lens's focal length); per lenslet, k1 and k2 follow by
linear least squares. The mount's axes may be turned about the array's axis relative to the lattice found by
the centres; one global angle, fitted jointly, absorbs that.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from lftransfer.imageio_utils import to_grey
from lftransfer.calibration.lenslets import NoSpotsError, find_lenslet_centres
from lftransfer.optics import LensArray, LensletDevice
from lftransfer.optics.geometry import apply_homography, rotation_2d
from lftransfer.rig.base import Rig
from lftransfer.rig.requests import Collimator

__all__ = ["DistortionFit", "collimator_directions", "fit_distortion", "calibrate_distortion"]


def collimator_directions(max_tan: float = 0.3, steps: int = 5) -> np.ndarray:
    """(N, 3) unit directions of a square grid of collimator tilts, |d_x / d_z|, |d_y / d_z| <= max_tan."""
    t = np.linspace(-max_tan, max_tan, steps)
    tx, ty = np.meshgrid(t, t)
    d = np.stack([tx.ravel(), ty.ravel(), np.ones(tx.size)], 1)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


@dataclass
class DistortionFit:
    """Per-lenslet radial distortion.

    Attributes:
        coefficients: (K, 2) k1, k2 per lenslet (0 where a lenslet had too few spots).
        mount_angle: rotation of the collimator mount's axes about the array's axis relative to the lattice,
            radians.
        rms: RMS residual of the focal-plane offsets, in units of the focal length (normalised coordinates).
        spots: number of spots used per lenslet, (K,).
    """

    coefficients: np.ndarray
    mount_angle: float
    rms: float
    spots: np.ndarray


def fit_distortion(k: np.ndarray, xn: np.ndarray, xd: np.ndarray, K: int, iterations: int = 6) -> DistortionFit:
    """Fit k1, k2 per lenslet and one mount angle to observed (lenslet, x_n, x_d) triples.

    Args:
        k: (M,) lenslet index of each observation.
        xn: (M, 2) ideal normalised coordinates of the beam in the mount's frame.
        xd: (M, 2) measured distorted normalised coordinates (focal-plane offset / focal length).
        K: number of lenslets.

    Returns:
        DistortionFit.
    """
    phi = 0.0
    coef = np.zeros((K, 2))
    counts = np.bincount(k, minlength=K)
    for _ in range(iterations):
        xr = xn @ rotation_2d(phi).T                                        # beam in the lattice's frame
        r2 = np.sum(xr * xr, axis=1)
        # per lenslet normal equations of xd - xr = xr (k1 r^2 + k2 r^4), both components stacked
        a1, a2 = xr * r2[:, None], xr * (r2 * r2)[:, None]
        y = xd - xr
        m11 = np.bincount(k, np.sum(a1 * a1, 1), K)
        m12 = np.bincount(k, np.sum(a1 * a2, 1), K)
        m22 = np.bincount(k, np.sum(a2 * a2, 1), K)
        b1 = np.bincount(k, np.sum(a1 * y, 1), K)
        b2 = np.bincount(k, np.sum(a2 * y, 1), K)
        det = m11 * m22 - m12 * m12
        ok = (counts >= 4) & (np.abs(det) > 1e-18)
        coef[:] = 0.0
        coef[ok, 0] = (m22[ok] * b1[ok] - m12[ok] * b2[ok]) / det[ok]
        coef[ok, 1] = (m11[ok] * b2[ok] - m12[ok] * b1[ok]) / det[ok]
        # mount angle: rotate the undistorted-by-model beam onto the measurements (2-D Procrustes)
        scale = 1.0 + coef[k, 0] * r2 + coef[k, 1] * r2 * r2
        z = xn * scale[:, None]
        phi = float(np.arctan2(np.sum(z[:, 0] * xd[:, 1] - z[:, 1] * xd[:, 0]), np.sum(z * xd)))
    xr = xn @ rotation_2d(phi).T
    r2 = np.sum(xr * xr, axis=1)
    pred = xr * (1.0 + coef[k, 0] * r2 + coef[k, 1] * r2 * r2)[:, None]
    rms = float(np.sqrt(np.mean(np.sum((pred - xd) ** 2, axis=1))))
    return DistortionFit(coefficients=coef, mount_angle=phi, rms=rms, spots=counts)


def calibrate_distortion(rig: Rig, array: LensArray, device: LensletDevice, levels: int, *, max_tan: float = 0.3,
                         steps: int = 5, progress=None) -> DistortionFit:
    """Sweep the collimator, find the spots, fit the distortion.

    Args:
        rig: the rig; it is asked for a :class:`~lftransfer.rig.requests.Collimator` at each tilt.
        array: the lens array in the model frame (from the lenslet centres).
        device: the LF camera's model (its homography from the lenslet centres; distortion unused).
        levels: the camera's full-scale code.
        max_tan, steps: collimator grid.
        progress: called with a message per capture.

    Returns:
        DistortionFit.
    """
    inv = np.linalg.inv(device.homography)
    ks, xns, xds = [], [], []
    for i, d in enumerate(collimator_directions(max_tan, steps)):
        if progress:
            progress(f"distortion: collimator tilt {i + 1}/{steps * steps}")
        try:
            rig.setup(Collimator(direction=tuple(d)))
            spots = find_lenslet_centres(to_grey(rig.capture_lf().codes, levels), array.lattice).centres
        except NoSpotsError:
            continue
        xn = -d[:2] / d[2]
        # where the undistorted model puts each lenslet's spot, and the detected spot nearest to it
        guess = array.centres + array.focal_length * xn
        guess_px = apply_homography(device.homography, guess)
        dist, j = cKDTree(spots).query(guess_px)
        pitch_px = np.median(np.linalg.norm(np.diff(guess_px[: array.cols], axis=0), axis=1))
        keep = dist < 0.25 * pitch_px
        q = apply_homography(inv, spots[j[keep]])
        kk = np.flatnonzero(keep)
        ks.append(kk)
        xns.append(np.broadcast_to(xn, (len(kk), 2)))
        xds.append((q - array.centres[kk]) / array.focal_length)
    if not ks:
        raise NoSpotsError("no collimator spots were found at any tilt")
    return fit_distortion(np.concatenate(ks), np.concatenate(xns), np.concatenate(xds), array.K)
