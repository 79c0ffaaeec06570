"""Step (a) of :mod:`lftransfer.calibration.radiometric`: the camera's response from an exposure bracket of a projector
ramp."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lftransfer.calibration.radiometric.common import _BRIGHT, _DARK, Progress, RadiometryError, _stride
from lftransfer.calibration.radiometric.focal_plane import _FocalPlane
from lftransfer.rig.requests import FocalPlaneDiffuser


def _fit_camera_gamma(codes: np.ndarray, exposures: np.ndarray, rng: np.random.Generator,
                      n_samples: int = 100) -> tuple[np.ndarray, np.ndarray, dict]:
    """Slope of log code against log exposure per channel.

    Args:
        codes: (E, P, 3) normalised codes of P pixels at E exposures.
        exposures: (E,) exposure scales.

    Returns:
        gamma (3,), linear signal at exposure 1 per pixel (P, 3) (NaN where not fitted), diagnostics.
    """
    x = np.log(exposures)[:, None, None]
    valid = (codes >= _DARK) & (codes <= _BRIGHT)
    y = np.log(np.where(valid, codes, 1.0))
    w = np.where(valid, codes, 0.0)                    # log noise falls with the code: weight bright samples
    sw = w.sum(0)
    ok = (valid.sum(0) >= 2) & (sw > 0)
    sw = np.where(ok, sw, 1.0)
    xm = (w * x).sum(0) / sw
    ym = (w * y).sum(0) / sw
    num = (w * (x - xm) * (y - ym)).sum(0)
    den = (w * (x - xm) ** 2).sum(0)
    ok &= den > 1e-9
    gamma = np.empty(3)
    signal = np.full(codes.shape[1:], np.nan)
    diag = {"samples": [], "pixels": []}
    for c in range(3):
        idx = np.flatnonzero(ok[:, c])
        if len(idx) < 50:
            raise RadiometryError(f"camera response: only {len(idx)} pixels of channel {'RGB'[c]} are neither "
                                  "dark nor saturated at two exposures; is the projector ramp visible?")
        slopes = num[idx, c] / den[idx, c]
        med = np.median(slopes)
        mad = 1.4826 * np.median(np.abs(slopes - med)) + 1e-6
        inl = idx[np.abs(slopes - med) <= 5 * mad]
        slope = num[inl, c].sum() / den[inl, c].sum()
        gamma[c] = 1.0 / slope
        # intercept: log c = (log s + log e) / gamma  ->  s (linear signal at e = 1)
        icpt = ym[inl, c] - slope * xm[inl, c]
        signal[inl, c] = np.exp(gamma[c] * icpt)
        pick = rng.choice(inl, min(n_samples, len(inl)), replace=False)
        xs = (signal[pick, c][None, :] * exposures[:, None])
        cs = codes[:, pick, c]
        keep = valid[:, pick, c]
        diag["samples"].append(np.stack([xs[keep], cs[keep]], 1).round(6).tolist())
        diag["pixels"].append(int(len(inl)))
    return gamma, signal, diag


@dataclass
class _CameraResponse:
    """Step (a): the camera's power-law response.

    Attributes:
        gamma: ``(3,)`` camera gamma per channel (``code = signal^(1/gamma)``).
        signal: ``(P, 3)`` linear signal at exposure scale 1 of the sampled ramp pixels (NaN where not fitted).
        scales: ``(E,)`` exposure scales of the bracket.
        image_shape: ``(H, W)`` of the LF camera, pixels.
        diag: the fit's diagnostics (response samples and pixel counts per channel).
    """

    gamma: np.ndarray
    signal: np.ndarray
    scales: np.ndarray
    image_shape: tuple[int, int]
    diag: dict

    def linear(self, codes_img: np.ndarray, e: float) -> np.ndarray:
        """Normalised codes -> linear signal per unit exposure scale."""
        return np.power(codes_img, self.gamma.astype(np.float32)) / np.float32(e)


def _measure_camera_response(fp: _FocalPlane, model, exposures: int, rng: np.random.Generator,
                             say: Progress) -> _CameraResponse:
    """Step (a): an exposure bracket of a projector ramp on the focal-plane diffuser; the camera's gamma from it.

    The bracket is ``exposures`` captures, factors of 2 apart, from exposure scale 1 (or longer, where the
    brightest pixels at 1 are below half scale), on a strided subset of about 60,000 pixels.

    Returns:
        The camera response: gamma per channel, the sampled pixels' linear signal, the exposure scales.
    """
    say(f"camera response: exposure bracket of a projector ramp ({exposures} captures)")
    fp.rig.setup(FocalPlaneDiffuser())
    prj_h, prj_w = fp.shape
    ramp = np.round(np.linspace(0, fp.levels, prj_w)).astype(fp.dtype)
    ramp_img = np.repeat(np.broadcast_to(ramp[None, :], (prj_h, prj_w))[..., None], 3, axis=2).copy()
    first = fp.capture(ramp_img, 1.0)
    h, w = first.shape[:2]
    stride = _stride(h, w, 60_000)
    top = 1.0
    nominal_gamma = np.asarray(model.camera.response.gamma)
    bright = np.quantile(first[::stride, ::stride].reshape(-1, 3), 0.999, axis=0)
    if np.all(bright < 0.5):                          # too dark at the normal exposure: lengthen the bracket
        peak = float(np.max(bright ** nominal_gamma))
        top = 1.5 / max(peak, 1e-4)
    scales = top * 0.5 ** np.arange(exposures)
    stack = [first[::stride, ::stride] if top == 1.0 else fp.capture(ramp_img, top)[::stride, ::stride]]
    stack += [fp.capture(ramp_img, e)[::stride, ::stride] for e in scales[1:]]
    codes = np.stack(stack).reshape(exposures, -1, 3).astype(np.float64)
    gamma, signal, diag = _fit_camera_gamma(codes, scales, rng)
    return _CameraResponse(gamma=gamma, signal=signal, scales=scales, image_shape=(h, w), diag=diag)
