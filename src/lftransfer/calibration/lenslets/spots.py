"""Spot images (step 1 of :mod:`lftransfer.calibration.lenslets`): background, detection, sub-pixel centres.

A collimated on-axis source seen through the lens array: one small spot per lenslet, its centroid the
lenslet's centre.
"""

from __future__ import annotations

import math
import warnings

import cv2
import numpy as np
from scipy.ndimage import median_filter
from scipy.spatial import cKDTree

from lftransfer.calibration.lenslets.common import NoSpotsError

_SNR = 5.0                 # detection threshold, noise sigmas of the smoothed image
_REL = 0.10                # ... and fraction of the brightest spot within two pitches
_REL_GLOBAL = 0.05         # ... and fraction of the bright spots anywhere (noise maxima far from the array)
_HOT = 0.8                 # (pixel - 3x3 median) / pixel above this: a hot pixel (a spot of sigma <~ 0.55 px)


def _noise_sigma(values: np.ndarray, clipped: bool) -> float:
    """Background noise sigma from one half of the distribution, leaving out bright pixels iteratively.

    Args:
        values: the (background-subtracted) image.
        clipped: the image's dark background was clipped (many pixels at the smallest code): the lower half of
            the distribution is then squeezed, so the upper half (84th percentile minus median) is used;
            otherwise the lower half (median minus 16th percentile), which dense spots do not widen.

    Pixels above median + 3 sigma (spots, which can cover a third of the image) are left out, and the estimate
    repeated, until none is left out.
    """
    v = values.ravel()
    if v.size > 400_000:
        v = v[:: v.size // 200_000]                               # a sample is enough
    q = 84.134 if clipped else 15.866

    def estimate(x):
        med, other = np.percentile(x, [50.0, q])
        return float(med), float(abs(other - med))

    med, sigma = estimate(v)
    for _ in range(10):
        kept = v[v < med + 3.0 * sigma]
        if kept.size < 16 or kept.size == v.size:
            break
        v = kept
        med, sigma = estimate(v)
    return sigma


def _background(img: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    """Smooth background: median of 16 (32 for images >= 256 px) pixel blocks, 3 x 3 block median, bilinear.

    Args:
        img: ``(H, W)`` image.
        mask: ``(H, W) bool``, True on pixels to leave out (spots); blocks with nothing left take the median
            of the other blocks.
    """
    h, w = img.shape
    b = 32 if min(h, w) >= 256 else 16
    nh, nw = -(-h // b), -(-w // b)
    data = img if mask is None else np.where(mask, np.nan, img)
    padded = np.pad(data, ((0, nh * b - h), (0, nw * b - w)), mode="edge")
    blocks = padded.reshape(nh, b, nw, b).transpose(0, 2, 1, 3).reshape(nh, nw, b * b)
    if mask is None:
        med = np.median(blocks, axis=2)
    else:
        counts = np.isfinite(blocks).sum(axis=2)
        ordered = np.sort(np.where(np.isfinite(blocks), blocks, np.inf), axis=2)       # NaN (masked) last
        lo = np.take_along_axis(ordered, np.maximum(counts - 1, 0)[..., None] // 2, axis=2)[..., 0]
        hi = np.take_along_axis(ordered, np.minimum(counts // 2, b * b - 1)[..., None], axis=2)[..., 0]
        some = counts >= max(8, b * b // 16)
        med = np.where(some, 0.5 * (lo + hi), np.nan)
        med[~some] = np.median(med[some]) if some.any() else float(np.median(img))
    med = median_filter(med, size=3, mode="nearest")
    return cv2.resize(med.astype(np.float32), (nw * b, nh * b), interpolation=cv2.INTER_LINEAR)[:h, :w].astype(
        np.float64)


def _blur(res: np.ndarray) -> np.ndarray:
    return cv2.GaussianBlur(res.astype(np.float32), (0, 0), 1.0, borderType=cv2.BORDER_REPLICATE)


def _residual(img: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Background-subtracted image (hot pixels replaced), its smoothed version (sigma 1 px) and that one's noise.

    The background and the noise are estimated up to three times, each time without the pixels that the
    previous pass found bright (spots and their wings, grown by 3 px), so that dense spots do not raise them.
    Hot pixels (more than 5 noise sigmas and more than 80 % of their own background-subtracted value above the
    median of their 3 x 3 neighbourhood; a Gaussian spot's peak is that sharp only for sigma < ~0.55 px) then
    take that median.
    """
    clipped = bool(np.count_nonzero(img <= img.min()) >= 0.02 * img.size)
    res = img - _background(img)
    mask = np.zeros(img.shape, bool)
    for _ in range(3):
        smooth = _blur(res)
        sample = smooth[~mask]
        noise = _noise_sigma(sample, clipped)
        bright = smooth > np.median(sample) + 3.0 * noise
        if not bright.any() or bright.mean() > 0.9:
            break
        grown = cv2.dilate(bright.astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool)
        mask = grown if grown.mean() <= 0.9 else bright
        res = img - _background(img, mask)
    med3 = cv2.medianBlur(res.astype(np.float32), 3).astype(np.float64)
    spike = res - med3
    hot = (spike > _SNR * _noise_sigma(res[~mask], clipped)) & (spike > _HOT * res)
    if hot.any():
        img = np.where(hot, img - res + med3, img)
        res = img - _background(img, mask | hot)
    smooth = _blur(res)
    return res, smooth, _noise_sigma(smooth[~mask], clipped)


def _detect_spots(img: np.ndarray) -> tuple[np.ndarray, float]:
    """Sub-pixel spot centres ``(N, 2)`` (x, y) pixels and the spots' sigma, pixels."""
    h, w = img.shape
    res, smooth, noise = _residual(img)
    top = float(smooth.max())
    if not top > 0:
        raise NoSpotsError("no lenslet spots found: the image is uniform (no bright spots on a darker background)")
    floor = max(_SNR * noise, 1e-4 * top)
    peaks = (smooth >= cv2.dilate(smooth, np.ones((5, 5), np.uint8))) & (smooth > floor)
    n, _, _, cent = cv2.connectedComponentsWithStats(peaks.astype(np.uint8), connectivity=8)
    if n <= 1:
        raise NoSpotsError(f"no lenslet spots found: nothing stands above the noise ({noise:.2g} of full scale)")
    xy = np.rint(cent[1:]).astype(np.int64)                          # plateaus -> one peak each
    xy[:, 0] = np.clip(xy[:, 0], 0, w - 1)
    xy[:, 1] = np.clip(xy[:, 1], 0, h - 1)
    x, y = xy[:, 0], xy[:, 1]
    amp = smooth[y, x].astype(np.float64)
    if len(xy) < 2:
        return xy.astype(np.float64), 1.0
    # Relative thresholds: 10 % of the brightest spot within about two pitches, 5 % of the bright ones anywhere.
    strong = amp >= 0.3 * np.percentile(amp, 90)
    if strong.sum() >= 2:
        d, _ = cKDTree(xy[strong]).query(xy[strong], k=2)
        pitch0 = float(np.median(d[:, 1]))
    else:
        pitch0 = float(max(h, w))
    k = min(19, len(xy))
    d, j = cKDTree(xy).query(xy, k=k, distance_upper_bound=2.2 * pitch0)
    neighbour_amp = np.where(np.isfinite(d), amp[np.minimum(j, len(xy) - 1)], 0.0)
    keep = (amp >= _REL * neighbour_amp.max(axis=1)) & (amp >= _REL_GLOBAL * np.percentile(amp, 95))
    xy, amp = xy[keep], amp[keep]
    sigma = _spot_sigma(res, xy, amp, pitch0)
    centres, ok = _windowed_centroids(res, xy, sigma, pitch0)
    margin = max(2.5 * sigma, 2.0)
    ok &= (centres[:, 0] >= margin) & (centres[:, 0] <= w - 1 - margin)
    ok &= (centres[:, 1] >= margin) & (centres[:, 1] <= h - 1 - margin)
    return centres[ok], sigma


def _spot_sigma(res: np.ndarray, xy: np.ndarray, amp: np.ndarray, pitch0: float) -> float:
    """Median Gaussian sigma of the brighter half of the spots, from 3-point log-parabolas along x and y."""
    h, w = res.shape
    inner = (xy[:, 0] >= 1) & (xy[:, 0] <= w - 2) & (xy[:, 1] >= 1) & (xy[:, 1] <= h - 2)
    sel = inner & (amp >= np.median(amp))
    x, y = xy[sel, 0], xy[sel, 1]
    sig = []
    for lo, mid, hi in ((res[y, x - 1], res[y, x], res[y, x + 1]), (res[y - 1, x], res[y, x], res[y + 1, x])):
        good = (lo > 0) & (mid > 0) & (hi > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            d2 = np.log(lo[good]) - 2 * np.log(mid[good]) + np.log(hi[good])
        sig.append(np.sqrt(-1.0 / d2[d2 < 0]))
    sig = np.concatenate(sig)
    sigma = float(np.median(sig)) if sig.size else 1.2
    return float(np.clip(sigma, 0.6, max(0.6, pitch0 / 6.0)))


def _windowed_centroids(res: np.ndarray, xy: np.ndarray, sigma: float, pitch: float, iterations: int = 60
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Gaussian-windowed centroids (window sigma = spot sigma) around integer peaks, iterated to convergence.

    Each spot's local background (median of an annulus between the spot and its neighbours) is subtracted
    first; pixels outside the image take no part. The fixed point is the centre of any symmetric spot.

    Args:
        res: ``(H, W)`` background-subtracted image.
        xy: ``(N, 2) int64`` integer peaks (x, y).
        sigma: spot sigma, pixels (also the window's).
        pitch: typical distance between neighbouring spots, pixels.
        iterations: most iterations.

    Returns:
        ``(N, 2) float64`` centres (x, y) pixels and ``(N,) bool`` convergence flags.
    """
    rad = int(math.ceil(4.0 * sigma)) + 1                       # window: the weights are < 1e-3 beyond
    r_in = min(4.0 * sigma + 1.0, max(3.0 * sigma, 0.3 * pitch))
    r_out = r_in + 2.0
    half = max(rad, int(math.ceil(r_out)))
    pad = np.pad(res, half, mode="constant", constant_values=np.nan)
    off = np.arange(-half, half + 1)
    cx, cy = xy[:, 0], xy[:, 1]
    patch = pad[(cy + half)[:, None, None] + off[None, :, None], (cx + half)[:, None, None] + off[None, None, :]]
    dist = np.hypot(off[:, None], off[None, :])
    annulus = (dist >= r_in) & (dist <= r_out)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)           # all-NaN annulus at a corner: no correction
        local_bg = np.nan_to_num(np.nanmedian(patch[:, annulus], axis=1), nan=0.0)
    core = (np.maximum(np.abs(off)[:, None], np.abs(off)[None, :]) <= rad)[None]
    values = np.where(core & np.isfinite(patch), patch - local_bg[:, None, None], 0.0)
    gx = (cx[:, None, None] + off[None, None, :]).astype(np.float64)
    gy = (cy[:, None, None] + off[None, :, None]).astype(np.float64)
    p = xy.astype(np.float64).copy()
    ok = np.ones(len(p), bool)
    inv2s2 = 1.0 / (2.0 * sigma * sigma)
    for _ in range(iterations):
        dx = gx - p[:, 0, None, None]
        dy = gy - p[:, 1, None, None]
        wv = np.exp(-(dx * dx + dy * dy) * inv2s2) * values
        s = wv.sum(axis=(1, 2))
        ok &= s > 0
        s = np.where(s > 0, s, 1.0)
        # For a Gaussian spot of the window's sigma, 2 * (windowed centroid - p) is the exact step; 1.5
        # under-relaxes it (robust to a wrong sigma or background), converging by a factor ~4 per iteration.
        step = 1.5 * np.stack([(wv * dx).sum(axis=(1, 2)), (wv * dy).sum(axis=(1, 2))], axis=1) / s[:, None]
        step = np.where(ok[:, None], np.clip(step, -1.0, 1.0), 0.0)
        p += step
        if np.max(np.abs(step), initial=0.0) < 1e-6:
            break
    ok &= np.all(np.abs(p - xy) <= 2.0, axis=1) & np.all(np.isfinite(p), axis=1)
    ok &= np.all(np.abs(step) < 1e-3, axis=1)                   # did not converge: no reliable centre
    return p, ok
