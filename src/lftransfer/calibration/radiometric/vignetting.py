"""Step (b) of :mod:`lftransfer.calibration.radiometric`: the camera's vignetting from a flat field."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from lftransfer.calibration.radiometric.camera_response import _CameraResponse
from lftransfer.calibration.radiometric.common import _BRIGHT, _DARK, _SATURATED, Progress, RadiometryError, _stride
from lftransfer.calibration.radiometric.focal_plane import _FocalPlane
from lftransfer.calibration.radiometric.result import VignettingPolynomial, _norm_coords, _terms


def _fit_vignetting(s: np.ndarray, mask: np.ndarray, degree: int, stride: int) -> tuple[VignettingPolynomial, dict]:
    """Polynomial fit to the channel-averaged, median-normalised flat field ``s`` (H, W, 3) on ``mask``."""
    h, w = mask.shape
    rows, cols = np.nonzero(mask[::stride, ::stride])
    rows, cols = rows * stride, cols * stride
    if len(rows) < 10 * len(_terms(degree)):
        raise RadiometryError(f"vignetting: only {len(rows)} usable flat-field pixels")
    vals = s[rows, cols]                                            # (N, 3)
    vals = (vals / np.median(vals, axis=0)).mean(axis=1)
    a = VignettingPolynomial.design(_norm_coords(cols, w), _norm_coords(rows, h), degree)
    keep = np.ones(len(vals), bool)
    for _ in range(3):
        coef, *_ = np.linalg.lstsq(a[keep], vals[keep], rcond=None)
        res = vals - a @ coef
        sigma = 1.4826 * np.median(np.abs(res[keep])) + 1e-12
        new = np.abs(res) <= 5 * sigma
        if np.array_equal(new, keep):
            break
        keep = new
    poly = VignettingPolynomial(degree, tuple(coef), (h, w), floor=0.0)
    peak = float(np.max(poly.map()[mask]))
    poly = VignettingPolynomial(degree, tuple(coef / peak), (h, w))
    rms = float(np.sqrt(np.mean((res[keep] / peak) ** 2)))
    return poly, {"fit_rms": rms, "pixels": int(keep.sum()), "rejected": int((~keep).sum())}


@dataclass
class _FlatField:
    """Step (b): the camera's vignetting from a flat field.

    Attributes:
        poly: the vignetting polynomial (1 at its maximum over the fitted area).
        vmap: ``(H, W) float32`` its map over the LF camera's pixels.
        mask: ``(H, W) bool`` the pixels the fit used (lit, neither dark nor saturated, eroded by 2 px).
        exposure: exposure scale of the flat field (nothing saturates at it).
        white: the full-code projector image that lit it.
        diag: the fit's diagnostics (RMS, pixels used and rejected).
    """

    poly: VignettingPolynomial
    vmap: np.ndarray
    mask: np.ndarray
    exposure: float
    white: np.ndarray
    diag: dict


def _measure_vignetting(fp: _FocalPlane, response: _CameraResponse, degree: int, say: Progress) -> _FlatField:
    """Step (b): a full-code projector image on the diffuser, linearised; a polynomial of ``degree`` fitted to it.

    The exposure starts where the brightest ramp pixels of step (a) reach 0.6 of full scale and halves (up to 6
    tries) until under 1e-4 of the lit pixels saturate.

    Returns:
        The flat field's fit, the pixels it used and its exposure scale.

    Raises:
        RadiometryError: the flat field saturates at every exposure tried, or too few pixels are usable.
    """
    say("camera vignetting: flat field")
    h, w = response.image_shape
    white = fp.uniform([fp.levels] * 3)
    peak_signal = float(np.nanmax(np.nanquantile(response.signal, 0.999, axis=0)))    # brightest ramp pixels, e = 1
    e_flat = 0.6 / max(peak_signal, 1e-6)
    for _ in range(6):
        flat = fp.capture(white, e_flat)
        lit = flat.max(axis=2) > _DARK
        if np.mean(flat[lit].max(axis=1) >= _SATURATED) < 1e-4:
            break
        e_flat *= 0.5
    else:
        raise RadiometryError("vignetting: the flat field saturates at every exposure tried")
    flat_lin = response.linear(flat, e_flat)
    level = np.median(flat_lin[lit], axis=0)
    mask = np.all((flat >= _DARK) & (flat <= _BRIGHT), axis=2) & np.all(flat_lin > 0.25 * level, axis=2)
    mask = cv2.erode(mask.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    poly, diag = _fit_vignetting(flat_lin, mask, degree, _stride(h, w, 200_000))
    return _FlatField(poly=poly, vmap=poly.map(), mask=mask, exposure=e_flat, white=white, diag=diag)
