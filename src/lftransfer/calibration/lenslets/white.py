"""White images (step 2 of :mod:`lftransfer.calibration.lenslets`): pitch, sub-image detection, centres of symmetry.

A uniformly lit diffuser in front of the array: one bright sub-image about a pitch wide per lenslet, whose
centre of symmetry is the image of the chief ray through the lenslet's centre.
"""

from __future__ import annotations

import math
import warnings

import cv2
import numpy as np
from scipy.spatial import cKDTree

from lftransfer.calibration.lenslets.common import NoSpotsError

_WHITE_SMOOTH = 0.2        # white images: detection smoothing sigma, pitches
_WHITE_WINDOW = 0.5        # ... centroid window radius, pitches
_WHITE_BRIGHT = 0.3        # ... a sub-image's brightness: mean within this radius (pitches) of its centre
_CELL_DISK = 0.72          # ... second pass: the cell window is cut by a disk of this radius (pitches; beyond the
                           #     corners of hex and rect cells) or of the distance to the image border
_WHITE_REL = 0.3           # ... a peak's contrast at least this fraction of the typical peak's
_WHITE_ENVELOPE = 0.1      # ... where the vignetting envelope is at least this fraction of its top


def _detect_white(img: np.ndarray, lattice: str) -> tuple[np.ndarray, float]:
    """Sub-pixel sub-image centres of a white image (see the module's docstring).

    The first pass uses a disk window of half the pitch everywhere. The second one divides out each
    sub-image's vignetting gradient and follows the distorted lattice: sub-images apart from each other (their
    mean radial profile falls to the dark gap within half a pitch) get a disk of half their local pitch
    (median distance to their nearest neighbours), touching ones their own lattice cell (:func:`_local_cells`,
    1 px in), so that no neighbour reaches into the window. Near the image border the window is cut by a
    disk that stays inside the image, down to the sub-images' extent (half the pitch if they touch); sub-images
    whose window would have to be smaller, and those whose mean brightness is below 75 % of the median of
    their neighbours' (cut by the edge of the lit area), are dropped.

    Args:
        img: ``(H, W)`` grey image.
        lattice: ``"hex"`` or ``"rect"`` (the shape of the cells).

    Returns:
        ``(N, 2) float64`` centres (x, y), pixels, and the median window radius (half the pitch), pixels.
    """
    h, w = img.shape
    pitch = _autocorr_pitch(img)
    env = _envelope(img, pitch)
    top = float(np.percentile(env, 99.0))
    if not top > 0:
        raise NoSpotsError("no lenslet sub-images found: the image is dark")
    norm = img / np.maximum(env, 0.05 * top)
    smooth = cv2.GaussianBlur(norm.astype(np.float32), (0, 0), _WHITE_SMOOTH * pitch,
                              borderType=cv2.BORDER_REPLICATE)
    size = 2 * int(round(0.35 * pitch)) + 1
    peaks = smooth >= cv2.dilate(smooth, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size)))
    size = 2 * int(round(0.65 * pitch)) + 1
    contrast = smooth - cv2.erode(smooth, np.ones((size, size), np.uint8))          # separable: fast
    peaks &= (env > _WHITE_ENVELOPE * top) & (contrast > 0)
    n, _, _, cent = cv2.connectedComponentsWithStats(peaks.astype(np.uint8), connectivity=8)
    if n <= 1:
        raise NoSpotsError("no lenslet sub-images found: no local maxima in the lit part of the image")
    xy = np.rint(cent[1:]).astype(np.int64)
    xy[:, 0] = np.clip(xy[:, 0], 0, w - 1)
    xy[:, 1] = np.clip(xy[:, 1], 0, h - 1)
    con = contrast[xy[:, 1], xy[:, 0]].astype(np.float64)
    xy = xy[con >= _WHITE_REL * np.percentile(con, 75)].astype(np.float64)
    if len(xy) >= 2:                                             # the pitch of the detections themselves
        d, _ = cKDTree(xy).query(xy, k=2)
        near = np.abs(d[:, 1] / pitch - 1.0) < 0.3
        if near.any():
            pitch = float(np.median(d[near, 1]))
    centres, ok = _disk_centroids(img, xy, _WHITE_WINDOW * pitch)
    centres = centres[ok]
    if len(centres) < 4:
        return centres, _WHITE_WINDOW * pitch                    # too few: find_lenslet_centres says so
    local_pitch = _local_pitch(centres, pitch)
    gamma, bright, typical = _relative_gradient(img, centres, _WHITE_BRIGHT * local_pitch, local_pitch)
    nominal = _WHITE_WINDOW * local_pitch
    extent = _subimage_extent(img, centres, nominal, bright)
    # Second pass. Sub-images apart: a disk of half the local pitch, smaller near the image border down to
    # the sub-images' own extent. Touching sub-images: the sub-image's own lattice cell (1 px in), which
    # keeps the neighbours out, cut by a disk that keeps it inside the image, down to half the pitch. A
    # sub-image cut by the border is dropped.
    if extent is None:
        extent = nominal - 0.5
        axes, apothem = _local_cells(centres, local_pitch, lattice)
        radius = np.minimum(_CELL_DISK * local_pitch, _inset(centres, (h, w)))
    else:
        extent = np.minimum(extent, nominal - 0.5)
        axes = apothem = None
        radius = np.minimum(nominal, _inset(centres, (h, w)))
    keep = (bright >= 0.75 * typical) & (radius >= extent)
    extent, radius, nominal = extent[keep], radius[keep], nominal[keep]
    if axes is not None:
        axes, apothem = axes[keep], apothem[keep]
    centres, ok = _disk_centroids(img, centres[keep], radius, gamma[keep], axes, apothem)
    ok[ok] &= np.minimum(radius[ok], _inset(centres[ok], (h, w)) + 0.5) >= extent[ok]
    centres, radius = centres[ok], np.minimum(radius[ok], nominal[ok])
    if len(centres) >= 2:                                        # two peaks that found one sub-image: one
        pairs = cKDTree(centres).query_pairs(0.3 * pitch, output_type="ndarray")
        if len(pairs):
            keep = np.ones(len(centres), bool)
            keep[pairs[:, 1]] = False
            centres, radius = centres[keep], radius[keep]
    return centres, float(np.median(radius)) if len(radius) else _WHITE_WINDOW * pitch


def _inset(xy: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """``(N,)`` distance (pixels) of points to the nearest image border (the outermost pixel centres)."""
    h, w = shape
    return np.minimum(np.minimum(xy[:, 0], w - 1 - xy[:, 0]), np.minimum(xy[:, 1], h - 1 - xy[:, 1]))


def _subimage_extent(img: np.ndarray, centres: np.ndarray, radius: np.ndarray, bright: np.ndarray
                     ) -> float | None:
    """Radius (pixels) of the sub-images: where their mean radial profile first falls to 5 % above its floor.

    The profile (0.25 px bins, each sub-image divided by its own brightness) is averaged over up to 400
    sub-images nearest the image centre, out to their window radius. Sub-images that touch never fall that
    far: then (or with too few sub-images) None.
    """
    h, w = img.shape
    sel = np.argsort(np.hypot(centres[:, 0] - (w - 1) / 2, centres[:, 1] - (h - 1) / 2))[:400]
    sel = sel[bright[sel] > 0]
    if len(sel) < 4:
        return None
    half = int(math.ceil(radius[sel].max())) + 1
    offi = np.arange(-half, half + 1)
    base = np.rint(centres[sel]).astype(np.int64)
    pad = np.pad(img.astype(np.float64), half, mode="constant", constant_values=np.nan)
    patch = pad[(base[:, 1] + half)[:, None, None] + offi[None, :, None],
                (base[:, 0] + half)[:, None, None] + offi[None, None, :]] / bright[sel, None, None]
    d = np.hypot((base[:, 0] - centres[sel, 0])[:, None, None] + offi[None, None, :],
                 (base[:, 1] - centres[sel, 1])[:, None, None] + offi[None, :, None])
    use = np.isfinite(patch) & (d <= radius[sel, None, None])
    bins = (d[use] / 0.25).astype(np.int64)
    counts = np.bincount(bins)
    prof = np.bincount(bins, weights=patch[use]) / np.maximum(counts, 1)
    prof = prof[counts > 0] if np.all(counts > 0) else prof[: np.argmin(counts > 0)]
    if len(prof) < 8:
        return None
    peak_at = int(np.argmax(prof))
    peak, floor = float(prof[peak_at]), float(prof[peak_at:].min())
    low = np.flatnonzero(prof[peak_at:] <= floor + 0.05 * (peak - floor))
    if not (len(low) and peak > floor) or (peak_at + low[0] + 1) * 0.25 > 0.98 * float(np.min(radius[sel])):
        return None
    return (peak_at + low[0] + 1) * 0.25


def _local_cells(centres: np.ndarray, local_pitch: np.ndarray, lattice: str) -> tuple[np.ndarray, np.ndarray]:
    """Each sub-image's lattice cell: directions to its neighbours and half their distances.

    The neighbours within 0.7..1.3 local pitches are sorted onto the lattice's K axes (3 for ``hex``, 2 for
    ``rect``) by their direction relative to the lattice's overall orientation; an axis' direction is the
    mean of its neighbours' (both signs) and its apothem half their mean distance, so the cell is centrally
    symmetric and follows the local distortion. Axes without neighbours take the overall direction and the
    mean of the other apothems (or half the local pitch).

    Returns:
        ``(N, K, 2)`` unit axes and ``(N, K)`` apothems, pixels.
    """
    n = len(centres)
    kk = 3 if lattice == "hex" else 2
    d, j = cKDTree(centres).query(centres, k=min(2 * kk + 3, n))
    d, j = d[:, 1:], j[:, 1:]
    near = (d > 0.7 * local_pitch[:, None]) & (d < 1.3 * local_pitch[:, None]) & (j < n)
    vec = centres[np.minimum(j, n - 1)] - centres[:, None, :]
    phi = np.arctan2(vec[..., 1], vec[..., 0])
    z = np.exp(2j * kk * phi)[near]
    theta = float(np.angle(np.mean(z))) / (2 * kk) if len(z) else 0.0
    sector = np.rint((phi - theta) / (math.pi / kk)).astype(np.int64)
    axis = sector % kk
    sign = np.where(sector % (2 * kk) < kk, 1.0, -1.0)                # the neighbours on both sides, one way
    unit = vec / np.maximum(d, 1e-9)[..., None] * sign[..., None]
    axes = np.zeros((n, kk, 2))
    apothem = np.zeros((n, kk))
    for k in range(kk):
        on = near & (axis == k)
        cnt = on.sum(axis=1)
        mean_dir = np.einsum("nm,nmi->ni", on.astype(np.float64), unit)
        default = np.array([math.cos(theta + k * math.pi / kk), math.sin(theta + k * math.pi / kk)])
        norm = np.linalg.norm(mean_dir, axis=1, keepdims=True)
        axes[:, k] = np.where((cnt > 0)[:, None] & (norm > 0), mean_dir / np.maximum(norm, 1e-12), default)
        apothem[:, k] = np.where(cnt > 0, 0.5 * (on * d).sum(axis=1) / np.maximum(cnt, 1), np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)           # no neighbour on any axis: half the pitch
        fill = np.nanmean(apothem, axis=1)
    fill = np.where(np.isfinite(fill), fill, 0.5 * local_pitch)
    apothem = np.where(np.isfinite(apothem), apothem, fill[:, None])
    return axes, apothem


def _local_pitch(xy: np.ndarray, pitch: float) -> np.ndarray:
    """``(N,)`` median distance of each point to its neighbours within 0.7..1.3 ``pitch`` (else ``pitch``)."""
    n = len(xy)
    if n < 2:
        return np.full(n, pitch)
    d, _ = cKDTree(xy).query(xy, k=min(7, n))
    d = np.where((d[:, 1:] > 0.7 * pitch) & (d[:, 1:] < 1.3 * pitch), d[:, 1:], np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)           # no neighbour: NaN -> the global pitch
        local = np.nanmedian(d, axis=1)
    return np.where(np.isfinite(local), local, pitch)


def _looks_white(img: np.ndarray) -> bool:
    """Mostly bright (median above a quarter of the maximum) with a lattice's period: a white image."""
    if not float(np.median(img)) > 0.25 * float(img.max()):
        return False
    try:
        _autocorr_pitch(img)
    except NoSpotsError:
        return False
    return True


def _autocorr_pitch(img: np.ndarray) -> float:
    """Lattice pitch (pixels) of a white image: distance of the nearest autocorrelation peak.

    The central crop (up to 512 px square) is high-passed (minus a Gaussian blur of an eighth of its size),
    Hann-windowed and zero-padded, so the autocorrelation is linear and falls off with the lag; its highest
    local maximum beyond 3 px (and within a quarter of the crop) is one of the nearest lattice neighbours; it
    must reach 10 % of the zero-lag value (a periodic image, not noise).
    """
    h, w = img.shape
    n = min(h, w, 512)
    if n < 16:
        raise NoSpotsError(f"no lenslet sub-images found: the image ({h} x {w}) is too small")
    y0, x0 = (h - n) // 2, (w - n) // 2
    crop = img[y0:y0 + n, x0:x0 + n].astype(np.float64)
    crop = crop - cv2.GaussianBlur(crop, (0, 0), n / 8.0, borderType=cv2.BORDER_REFLECT)
    win = np.hanning(n)
    spec = np.fft.rfft2(crop * win[:, None] * win[None, :], s=(2 * n, 2 * n))
    ac = np.fft.fftshift(np.fft.irfft2(np.abs(spec) ** 2, s=(2 * n, 2 * n)))
    m = n // 4
    ac = ac[n - m:n + m + 1, n - m:n + m + 1].astype(np.float32)
    if not ac[m, m] > 0:
        raise NoSpotsError("no lenslet sub-images found: the image is uniform")
    off = np.arange(-m, m + 1)
    r = np.hypot(off[:, None], off[None, :])
    local = (ac >= cv2.dilate(ac, np.ones((5, 5), np.uint8))) & (r > 3.0) & (r < m - 2)
    if not local.any():
        raise NoSpotsError("no lenslet sub-images found: the image has no periodic structure")
    vals = np.where(local, ac, -np.inf)
    best = float(vals.max())
    if not best > 0.1 * ac[m, m]:
        raise NoSpotsError("no lenslet sub-images found: the image has no periodic structure")
    r1 = float(r.ravel()[np.argmax(vals)])
    close = local & (ac > 0.5 * best) & (r < 1.3 * r1)           # the shell of nearest neighbours
    return float(np.median(r[close]))


def _envelope(img: np.ndarray, pitch: float) -> np.ndarray:
    """Vignetting envelope of a white image: Gaussian blur of sigma one pitch (on a reduced copy), full size.

    The blur attenuates the lattice's period by ``exp(-2 pi^2)``; the copy is reduced by block means of less
    than a sixth of the pitch, well below the lattice's Nyquist limit.
    """
    h, w = img.shape
    f = max(1, int(pitch // 6))
    small = cv2.resize(img.astype(np.float32), (max(1, w // f), max(1, h // f)), interpolation=cv2.INTER_AREA)
    small = cv2.GaussianBlur(small, (0, 0), pitch / f, borderType=cv2.BORDER_REFLECT)
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR).astype(np.float64)


def _patches(pad: np.ndarray, b: np.ndarray, half: int, gamma: np.ndarray | None, rel: np.ndarray) -> np.ndarray:
    """(n, 2 half + 1, 2 half + 1) float32 patches of the padded image ``pad`` (padded by ``half``, NaN outside:
    taken as 0) around the integer positions ``b`` (n, 2) (x, y); with ``gamma`` (n, 2) the brightness gradient
    divided out, relative to the start ``b - rel``."""
    offi = np.arange(-half, half + 1)
    off = offi.astype(np.float32)
    patch = pad[(b[:, 1] + half)[:, None, None] + offi[None, :, None],
                (b[:, 0] + half)[:, None, None] + offi[None, None, :]]
    patch = np.where(np.isfinite(patch), patch, np.float32(0.0))
    if gamma is None:
        return patch
    g = gamma.astype(np.float32)
    rel = rel.astype(np.float32)
    tilt = 1.0 + g[:, 0, None, None] * (off[None, None, :] + rel[:, 0, None, None]) \
        + g[:, 1, None, None] * (off[None, :, None] + rel[:, 1, None, None])
    return patch / np.maximum(tilt, np.float32(0.1))


def _window(qa: np.ndarray, off: np.ndarray, outer2: np.ndarray, inv_ramp: np.ndarray,
            cell: tuple[np.ndarray, np.ndarray] | None) -> np.ndarray:
    """(n, P, P) float32 window weights around the centres ``qa`` (n, 2) (patch offsets ``off``): the disk's soft
    edge (``outer2``, ``inv_ramp`` (n, 1, 1)), cut to the lattice cell where ``cell`` gives its axes (n, K, 2)
    and apothems less 1 (n, K)."""
    r2 = (off[None, None, :] - qa[:, 0, None, None]) ** 2 + (off[None, :, None] - qa[:, 1, None, None]) ** 2
    wgt = np.clip((outer2 - r2) * inv_ramp, 0.0, 1.0)
    if cell is None:
        return wgt
    ax, ap = cell
    dxa = off[None, None, :] - qa[:, 0, None, None]
    dya = off[None, :, None] - qa[:, 1, None, None]
    for k in range(ax.shape[1]):
        proj = np.abs(ax[:, k, 0, None, None] * dxa + ax[:, k, 1, None, None] * dya)
        wgt = np.minimum(wgt, np.clip(0.5 * (ap[:, k, None, None] - proj), 0.0, 1.0))
    return wgt


def _disk_centroids(img: np.ndarray, xy: np.ndarray, radius, gamma: np.ndarray | None = None,
                    axes: np.ndarray | None = None, apothem: np.ndarray | None = None, iterations: int = 60,
                    chunk: int = 1024) -> tuple[np.ndarray, np.ndarray]:
    """Centroids of the image within a flat disk (or cell) window (soft edge) iterated to their fixed points.

    The fixed point of a centrally symmetric window is the centre of any centrally symmetric sub-image it
    holds, neighbours included (a lattice is centrally symmetric about each node, to first order in the
    distortion). The disk window's weight is ``clip(((radius + 1)^2 - r^2) / (4 radius), 0, 1)``: 1 within
    about ``radius - 1``, 0 beyond ``radius + 1``. The iteration converges geometrically (what the window's
    rim cuts moves with it); it is sped up by extrapolating the geometric series of the steps (Aitken). The
    patches are cut around the rounded start with a 3 px margin around the window, the most a centre may
    move.

    Args:
        img: ``(H, W)`` image.
        xy: ``(N, 2)`` start positions (x, y), pixels.
        radius: ``(N,)`` window radii, pixels.
        gamma: ``(N, 2)`` relative brightness gradient (1/px) of each sub-image's surroundings, divided out of
            its window (``image / (1 + gamma . (x - start))``), or None.
        axes: ``(N, K, 2)`` unit vectors towards the neighbours (K = 3 for ``hex``, 2 for ``rect``) and
        apothem: ``(N, K)`` half the neighbour distances, pixels: the window is also cut to the sub-image's
            lattice cell, ``|axis . (x - c)| <= apothem - 1`` (weight falling from 1 to 0 over the 2 px inside
            that), which keeps the neighbours of touching sub-images out; or None.
        iterations: most iterations per stage.
        chunk: sub-images processed at once (memory).

    Returns:
        ``(N, 2) float64`` centres (x, y) and ``(N,) bool`` flags (converged to 1e-3 px, moved less than a
        third of the radius from the start, window not empty).
    """
    radius = np.broadcast_to(np.asarray(radius, dtype=np.float64), (len(xy),))
    half = int(math.ceil(radius.max(initial=1.0) + 1.0)) + 3
    pad = np.pad(img.astype(np.float32), half, mode="constant", constant_values=np.nan)
    offi = np.arange(-half, half + 1)
    off = offi.astype(np.float32)
    outer2 = ((radius + 1.0) ** 2).astype(np.float32)[:, None, None]
    inv_ramp = (1.0 / (4.0 * radius)).astype(np.float32)[:, None, None]
    if axes is not None:
        ax32 = np.asarray(axes, dtype=np.float32)
        ap32 = (np.asarray(apothem, dtype=np.float64) - 1.0).astype(np.float32)   # weight 0 there, 1 at -2
    start = np.asarray(xy, dtype=np.float64)
    p = start.copy()
    ok = np.ones(len(p), bool)
    base = np.rint(p).astype(np.int64)
    for s in range(0, len(p), chunk):
        sl = slice(s, s + chunk)
        b = base[sl]
        patch = _patches(pad, b, half, None if gamma is None else gamma[sl], b - start[sl])
        q = p[sl] - b
        step, prev = np.zeros_like(q), np.zeros_like(q)
        active, good = np.ones(len(q), bool), np.ones(len(q), bool)
        for it in range(iterations):
            a = np.flatnonzero(active)
            if not len(a):
                break
            qa = q[a].astype(np.float32)
            wgt = _window(qa, off, outer2[sl][a], inv_ramp[sl][a],
                          None if axes is None else (ax32[sl][a], ap32[sl][a]))
            wv = wgt * patch[a]
            cols = wv.sum(axis=1, dtype=np.float64)          # (n, P): sums over rows
            rows = wv.sum(axis=2, dtype=np.float64)
            tot = cols.sum(axis=1)
            fine = tot > 0
            tot = np.where(fine, tot, 1.0)
            st = np.stack([cols @ offi, rows @ offi], axis=1) / tot[:, None] - q[a]
            st = np.where(fine[:, None], np.clip(st, -1.0, 1.0), 0.0)
            good[a] &= fine
            # Aitken: steps shrinking by a ratio rho sum to step / (1 - rho)
            pr = prev[a]
            rho = np.sum(st * pr, axis=1) / np.maximum(np.sum(pr * pr, axis=1), 1e-30)
            accel = np.where((it >= 1) & (rho > 0.0) & (rho < 0.95), 1.0 / (1.0 - np.clip(rho, 0.0, 0.9)), 1.0)
            prev[a] = st
            q[a] = np.clip(q[a] + st * accel[:, None], -3.0, 3.0)
            step[a] = st
            active[a] = np.max(np.abs(st), axis=1) >= 2e-5
        p[sl] = b + q
        ok[sl] &= good & np.all(np.abs(step) < 1e-3, axis=1)
    ok &= np.all(np.isfinite(p), axis=1) & (np.linalg.norm(p - start, axis=1) < radius / 3.0)
    return p, ok


def _relative_gradient(img: np.ndarray, centres: np.ndarray, radius: np.ndarray, pitch: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each sub-image's relative brightness gradient (1/px) from its neighbours' mean brightness.

    The mean of the image in each sub-image's window (symmetric, so blind to the sub-image's own tilt) is a
    sample of the vignetting at its centre; a plane fitted (least squares) to the samples within 2.3 pitches
    gives the gradient, divided by the plane's value at the centre. Zero where fewer than four neighbours or
    a degenerate spread.

    Args:
        img: ``(H, W)`` image.
        centres: ``(N, 2)`` sub-image centres, pixels.
        radius: ``(N,)`` window radii, pixels.
        pitch: ``(N,)`` local pitch, pixels.

    Returns:
        ``(N, 2) float64`` ``(d/dx, d/dy)`` of the relative brightness, ``(N,)`` window means and ``(N,)`` the
        median window mean of the sub-images within 1.5 pitches (itself included).
    """
    n = len(centres)
    half = int(math.ceil(radius.max(initial=1.0) + 1.0))
    offi = np.arange(-half, half + 1)
    base = np.rint(centres).astype(np.int64)
    pad = np.pad(img.astype(np.float32), half, mode="constant", constant_values=np.nan)
    bright = np.empty(n)
    for s in range(0, n, 2048):
        b, c, rad = base[s:s + 2048], centres[s:s + 2048], radius[s:s + 2048, None, None]
        patch = pad[(b[:, 1] + half)[:, None, None] + offi[None, :, None],
                    (b[:, 0] + half)[:, None, None] + offi[None, None, :]]
        dx = (b[:, 0] - c[:, 0])[:, None, None] + offi[None, None, :]
        dy = (b[:, 1] - c[:, 1])[:, None, None] + offi[None, :, None]
        wgt = np.clip(((rad + 1.0) ** 2 - dx * dx - dy * dy) / (4.0 * rad), 0.0, 1.0) * np.isfinite(patch)
        bright[s:s + 2048] = (wgt * np.nan_to_num(patch)).sum(axis=(1, 2)) / np.maximum(wgt.sum(axis=(1, 2)), 1e-9)
    if n < 4:
        return np.zeros((n, 2)), bright, bright.copy()
    k = min(19, n)
    d, j = cKDTree(centres).query(centres, k=k, distance_upper_bound=2.3 * float(np.max(pitch)))
    jj = np.minimum(j, n - 1)
    valid = (d <= 2.3 * pitch[:, None]).astype(np.float64)
    near = np.where(d <= 1.5 * pitch[:, None], bright[jj], np.nan)
    typical = np.nanmedian(near, axis=1)                         # itself at least: never all NaN
    rel = (centres[jj] - centres[:, None, :]) * valid[..., None]
    x = np.concatenate([valid[..., None], rel], axis=2)          # (N, k, 3): [1, dx, dy]
    a = np.einsum("nki,nkj->nij", x, x)
    rhs = np.einsum("nki,nk->ni", x, bright[jj] * valid)
    spread = np.linalg.eigvalsh(a[:, 1:, 1:] - np.einsum("ni,nj->nij", a[:, 0, 1:], a[:, 0, 1:])
                                / np.maximum(a[:, 0, 0], 1.0)[:, None, None])[:, 0]
    fine = (valid.sum(axis=1) >= 4) & (spread > 0.5 * pitch * pitch)
    gamma = np.zeros((n, 2))
    if fine.any():
        beta = np.linalg.solve(a[fine], rhs[fine][..., None])[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            g = beta[:, 1:] / beta[:, :1]
        gamma[fine] = np.where(np.isfinite(g) & (beta[:, :1] > 0), g, 0.0)
    return gamma, bright, typical
