"""Step (c) of :mod:`lftransfer.calibration.radiometric`: the projector's response, cross-talk and black level from
uniform images."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lftransfer.calibration.radiometric.camera_response import _CameraResponse
from lftransfer.calibration.radiometric.common import _SATURATED, Progress
from lftransfer.calibration.radiometric.focal_plane import _FocalPlane
from lftransfer.calibration.radiometric.vignetting import _FlatField


def _fit_power(levels: np.ndarray, d: np.ndarray) -> tuple[float, np.ndarray, float]:
    """``d[n, c] ~ A[c] * levels[n]^gamma``: gamma by a bounded scalar search, A by linear least squares."""
    from scipy.optimize import minimize_scalar

    def amplitude(g):
        r = levels ** g
        return r, (r @ d) / (r @ r)

    def cost(g):
        r, amp = amplitude(g)
        return float(np.sum((d - r[:, None] * amp[None, :]) ** 2))

    best = minimize_scalar(cost, bounds=(0.1, 8.0), method="bounded", options={"xatol": 1e-7})
    g = float(best.x)
    r, amp = amplitude(g)
    rms = math.sqrt(cost(g) / d.size)
    return g, amp, rms


@dataclass
class _ProjectorFit:
    """Step (c): the projector's response, cross-talk and black level (up to a common gain).

    Attributes:
        gamma: ``(3,)`` projector gamma per channel (``drive = code^gamma``).
        cross_talk: ``(3, 3)`` C, the mean of its diagonal 1.
        black_level: ``(3,)`` b on the scale of C, clipped to [0, 0.199].
        scale: ``s``, the mean diagonal of ``G C``: focal-plane signal per unit exposure scale of one channel
            at full code.
        levels: ``(L,) int`` the projector codes of the uniform levels.
        black: ``(3,)`` linear signal of the black image (per unit exposure scale, vignetting divided out).
        black_exposure: exposure scale of the black image.
        samples: ``(3, L, 3)`` linear signal of each projector channel (first axis) at each level.
        fit_rms: ``(3,)`` RMS residual of each channel's power-law fit, relative to its diagonal gain.
        response_samples: per channel, ``(normalised code, measured normalised drive)`` pairs.
    """

    gamma: np.ndarray
    cross_talk: np.ndarray
    black_level: np.ndarray
    scale: float
    levels: np.ndarray
    black: np.ndarray
    black_exposure: float
    samples: np.ndarray
    fit_rms: list
    response_samples: list


def _measure_projector(fp: _FocalPlane, response: _CameraResponse, flat: _FlatField, projector_levels: int,
                       say: Progress) -> _ProjectorFit:
    """Step (c): uniform projector images (black, then ``projector_levels`` levels per channel), mean signals.

    Each capture's codes are linearised by (a), divided by the vignetting of (b) and averaged over a central
    region (vignetting >= 0.85 within the flat field's mask, strided to about 200,000 pixels); the black image
    is captured at 8 times the flat field's exposure unless that saturates. Per projector channel a power law
    is fitted to the levels' signals minus black's.

    Returns:
        The projector's gamma, cross-talk, black level and the measurements behind them.
    """
    n_lv = np.unique(np.round(np.linspace(0, fp.levels, projector_levels + 1)[1:]).astype(int))
    say(f"projector response, cross-talk, black level ({1 + 3 * len(n_lv)} captures)")
    vmap, e_flat = flat.vmap, flat.exposure
    region = flat.mask & (vmap >= 0.85)
    if region.sum() < 100:
        region = flat.mask
    rs = max(1, int(math.ceil(math.sqrt(region.sum() / 200_000))))
    sub = np.zeros_like(region)
    sub[::rs, ::rs] = region[::rs, ::rs]
    region = sub
    inv_vig = (1.0 / vmap[region])[:, None]

    def measure(image: np.ndarray, e: float) -> tuple[np.ndarray, bool]:
        img = fp.capture(image, e)[region]
        return (response.linear(img, e) * inv_vig).mean(axis=0).astype(np.float64), bool(np.any(img >= _SATURATED))

    e_black = 8 * e_flat
    black, saturated = measure(fp.uniform([0, 0, 0]), e_black)
    if saturated:                                   # a bright black level: the normal exposure then suffices
        e_black = e_flat
        black, _ = measure(fp.uniform([0, 0, 0]), e_black)
    samples = np.zeros((3, len(n_lv), 3))
    for j in range(3):
        for i, n in enumerate(n_lv):
            code = [0, 0, 0]
            code[j] = int(n)
            samples[j, i], _ = measure(fp.uniform(code), e_flat)
    gain_ct = np.zeros((3, 3))                            # G * C
    projector_gamma = np.zeros(3)
    rms = []
    x_lv = n_lv / fp.levels
    prj_samples = []
    for j in range(3):
        d = samples[j] - black[None, :]
        projector_gamma[j], gain_ct[:, j], r = _fit_power(x_lv, d)
        rms.append(float(r / gain_ct[j, j]))
        prj_samples.append(np.stack([x_lv, d[:, j] / gain_ct[j, j]], 1).round(7).tolist())
    s = float(np.mean(np.diag(gain_ct)))
    return _ProjectorFit(gamma=projector_gamma, cross_talk=gain_ct / s, black_level=np.clip(black / s, 0.0, 0.199),
                         scale=s, levels=n_lv, black=black, black_exposure=e_black, samples=samples, fit_rms=rms,
                         response_samples=prj_samples)
