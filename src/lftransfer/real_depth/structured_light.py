"""The real scene's depth from the projector and the view camera as a structured-light pair
(docs/architecture.md, "Occlusion").

A projector behind a lens array is no pinhole projector: one projector pixel lights a beam as wide as its lenslet,
and every point in front of the array is lit by dozens of lenslets at once, each through another pixel. Gray codes
per projector pixel (OpenCV's ``structured_light`` module) therefore do not decode: a view pixel sees the codes of
many pixels summed. What does decode is a code carried by the *rays*: the rig draws phase-shifted sinusoidal
fringes on a plane at depth z0 (:func:`lftransfer.calibration.pose.fringe_lightfields`, the pose calibration's
patterns), each beam carrying the phase of the point where it meets that plane. A real point at depth z is lit by
the lenslets k whose window of directions holds it; the beam from lenslet k through it meets the plane at
``c_k + (x - c_k) z0 / z``, so what the point receives is the sum of those beams' sinusoids, one complex phasor per
fringe set:

    Z(x) = sum_k w_k(x) exp(2 pi i a_k(x) / T) / sum_k w_k(x),    a_k = that meeting point along the fringes' axis

(w_k: the beam's irradiance there, (z / r)^3 inside lenslet k's window, 0 outside). On the drawing plane every
beam agrees (full contrast); off it the phasors spread (the contrast falls, the phase moves with the lenslets
behind the point). The model knows Z for any point (it needs only the calibrated lenslets and array pose, never the
real objects), and four phase steps give each view pixel's observed phasor, so each view pixel's depth is the
distance along its ray whose predicted phasors best match the observed ones: a sweep along the ray (coarse, then
fine around the best), over fringe sets drawn on several planes and at two periods (the coarse period leaves one
candidate, the fine ones place it).

Not OpenCV's module, then, and not the pinhole triangulation it assumes: the decode is a matched filter against
the rig model's own prediction, on numpy.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np

from lftransfer.lightfield import LightField
from lftransfer.optics.geometry import pixel_rays
from lftransfer.real_depth.lightfield import MIN_SIGMA_M, ViewDepth
from lftransfer.rig.base import Rig
from lftransfer.rig.requests import ViewCapture

__all__ = ["FRINGE_SETS", "FringeSet", "SHIFTS", "decode_structured_light", "measure_structured_light",
           "predicted_phasors", "structured_light_patterns"]

SHIFTS = 4                     # phase steps per fringe set


@dataclass(frozen=True)
class FringeSet:
    """Fringes along one axis of the array, drawn on the plane ``z = plane_m`` (array frame), period ``period_m``."""

    plane_m: float
    axis: int                  # 0: along x, 1: along y
    period_m: float


#: The rig's structured light: a coarse period that leaves one candidate over the whole real side, and fine periods
#: drawn on two planes that bracket where real objects stand (8 and 12 cm in the paper's scenes); x and y each.
FRINGE_SETS: tuple[FringeSet, ...] = tuple(FringeSet(z, a, t) for z, t in ((0.09, 0.30), (0.06, 0.06), (0.12, 0.06))
                                           for a in (0, 1))
DEPTH_RANGE_M = (0.005, 0.30)  # where along its ray a view pixel's real surface is looked for (array-frame z)
MAX_STRETCH_M = 0.6            # the longest stretch of a ray searched, metres (a ray grazing the array's plane)
COARSE_SEARCH_M = 0.012        # the first sweep's step along the ray (the coarse fringes only), metres
COARSE_STEP_M = 0.003          # the second sweep's step (every set), metres; then refined
FINE_STEPS = 9                 # samples across two coarse steps around the best, then a parabola
MIN_MODULATION = 0.08          # a pixel whose coarse fringes modulate less than this (over their mean) has no depth
MIN_SNR = 5.0                  # ... or whose coarse fringes' amplitude is below this many times its images' noise
MIN_FIT = 0.9                  # ... or whose fringes the model's best distance explains worse than this (a cosine)
NOISE_WINDOW = 5               # pixels: the images' noise is estimated over this neighbourhood
MODEL_SIGMA_M = 0.002          # what the rig model's prediction is trusted to, metres (added to the noise's part)
CHUNK = 200_000                # candidate points per batch (memory: CHUNK x lenslets complex values)


def structured_light_patterns(model, U: int, V: int, radiance: float,
                              sets: tuple[FringeSet, ...] = FRINGE_SETS) -> list[LightField]:
    """The light fields of every fringe set, :data:`SHIFTS` phase steps each (set-major), in the model frame."""
    from lftransfer.lightfield.fringes import BoardPattern, fringe_lightfields

    out: list[LightField] = []
    drawn: dict[tuple[float, float], list[LightField]] = {}
    for s in sets:
        key = (s.plane_m, s.period_m)
        if key not in drawn:       # fringe_lightfields draws both axes at once
            plane = BoardPattern(np.array([0.0, 0.0, s.plane_m]), np.array([0.0, 0.0, -1.0]), np.array([1.0, 0.0, 0.0]),
                                 np.array([0.0, 1.0, 0.0]))
            drawn[key] = fringe_lightfields(model.array, U, V, plane, (4.0, 4.0), radiance, period_m=s.period_m,
                                            shifts=SHIFTS)
        out.extend(drawn[key][s.axis * SHIFTS:(s.axis + 1) * SHIFTS])
    return out


def measure_structured_light(rig: Rig, model, view, encoder, U: int, *, spp: int = 16,
                             sets: tuple[FringeSet, ...] = FRINGE_SETS,
                             progress: Callable[[str], None] | None = None) -> ViewDepth:
    """Project the fringes on the real scene, photograph each with the view camera, decode
    (:func:`decode_structured_light`). Leaves the projector black.

    Args:
        rig: the rig, in its real scene (:class:`~lftransfer.rig.requests.RealScene`).
        model: the calibrated :class:`~lftransfer.rig.RigModel`.
        view: the view camera (``ViewConfig``).
        encoder: the model's light field -> projector image encoder (``model.encoder(U, U)``).
        U: angular samples of the patterns.
        spp: view camera quality of each photograph.
        progress: called with a message per photograph.
    """
    patterns = structured_light_patterns(model, U, U, 0.9 * model.projector.max_radiance, sets)
    images = []
    for i, lf in enumerate(patterns):
        if progress:
            progress(f"structured light: fringes {i + 1} of {len(patterns)}")
        rig.project(encoder(lf))
        images.append(rig.capture_view(ViewCapture(quality=spp)).radiance.mean(axis=2))
    rig.project(rig.info.black())
    return decode_structured_light(np.stack(images), model, view, sets)


def predicted_phasors(points: np.ndarray, model, sets: tuple[FringeSet, ...]) -> np.ndarray:
    """What each fringe set draws at ``points``, by the rig model.

    Args:
        points: (N, 3) array-frame points (z > 0), metres.
        model: the rig model (its lenslets and their window of directions).
        sets: the fringe sets.

    Returns:
        (S, N) complex: per set, the beams' phasors summed with their irradiance over their total (modulus 1 on the
        drawing plane where all agree; 0 where no lenslet lights the point).
    """
    array = model.array
    c = array.centres                                         # (K, 2)
    out = np.zeros((len(sets), len(points)), np.complex64)
    for lo in range(0, len(points), max(1, CHUNK // len(c))):
        p = points[lo:lo + max(1, CHUNK // len(c))].astype(np.float32)
        front = p[:, 2:3] > 0                                 # (n, 1): only points in front of the array are lit
        z = np.where(front, p[:, 2:3], np.float32(1.0))
        rel = p[:, None, :2] - c[None].astype(np.float32)     # (n, K, 2) from each lenslet's centre
        uv = np.where(front[..., None], rel / z[..., None], np.float32(1e3))   # direction from the lenslet / its z
        lit = array.in_cell(-array.focal_length * uv)         # the lenslet's window (as LightField.mask has it)
        w = lit * (1.0 + np.square(uv).sum(-1)) ** -1.5       # (z / r)^3
        total = w.sum(1)
        for si, s in enumerate(sets):
            meet = c[None, :, s.axis].astype(np.float32) + rel[..., s.axis] * np.float32(s.plane_m) / z
            phase = meet * np.float32(2 * np.pi / s.period_m)           # where each beam meets the plane, as a phase
            phasor = (w * np.cos(phase)).sum(1) + 1j * (w * np.sin(phase)).sum(1)
            out[si, lo:lo + len(p)] = np.where(total > 0, phasor / np.where(total > 0, total, 1.0), 0.0)
    return out


def _observed(images: np.ndarray, n_sets: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per set and pixel the observed phasor (modulation over mean, at the fringes' phase), the mean, and the
    noise of one image estimated from the four steps' residual: (S, H, W) complex, (S, H, W), (H, W)."""
    h, w = images.shape[1:]
    I = images.reshape(n_sets, SHIFTS, h, w).astype(np.float64)
    steps = np.exp(-2j * np.pi * np.arange(SHIFTS) / SHIFTS)
    mean = I.mean(1)
    with np.errstate(divide="ignore", invalid="ignore"):
        phasor = 2.0 * np.einsum("sm...,m->s...", I, steps) / SHIFTS / mean
    # four steps fit a + b cos(phi + step) with one degree of freedom left: I0 - I1 + I2 - I3 = 0 but for noise
    resid = (I[:, 0] - I[:, 1] + I[:, 2] - I[:, 3]) / SHIFTS
    noise = 2.0 * np.sqrt(np.mean(np.square(resid), axis=0))  # per image: std(resid) = sigma / 2
    noise = np.sqrt(np.maximum(cv2.blur(np.square(noise), (NOISE_WINDOW, NOISE_WINDOW)), 0.0))   # steadier, locally
    return np.nan_to_num(phasor), mean, noise


def _score(pred: np.ndarray, obs: np.ndarray) -> np.ndarray:
    """Matched filter of predicted phasors (S, ...) against observed ones (S, ...): Re <pred, obs> / |pred|."""
    num = np.real(np.conj(pred) * obs).sum(0)
    den = np.sqrt(np.square(np.abs(pred)).sum(0))
    return np.where(den > 0, num / np.where(den > 0, den, 1.0), -np.inf)


def _searched_stretch(view, model, xs: np.ndarray, ys: np.ndarray):
    """Each pixel's ray in the array's frame and the stretch of it searched, where lo < z < hi
    (:data:`DEPTH_RANGE_M`), at most :data:`MAX_STRETCH_M` long.

    Returns:
        o (3,): the camera's centre; d (P, 3): the rays, per world metre along them (the frames may scale);
        s_lo (P,): where the stretch starts, metres along the ray; span (P,): its length (0 where none); ok (P,):
        whether the ray has one.
    """
    origin, rays = pixel_rays(view, np.stack([xs, ys], -1).astype(np.float64))
    m = np.asarray(model.world_to_array(), np.float64)
    o = m[:3, :3] @ np.asarray(origin, np.float64).reshape(3) + m[:3, 3]
    d = rays @ m[:3, :3].T
    lo_z, hi_z = DEPTH_RANGE_M
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (lo_z - o[2]) / d[:, 2], (hi_z - o[2]) / d[:, 2]
    s_lo = np.clip(np.minimum(t1, t2), 0.0, None)
    s_hi = np.minimum(np.maximum(t1, t2), s_lo + MAX_STRETCH_M)      # a ray along the array's plane: its first part
    ok = np.isfinite(s_lo) & np.isfinite(s_hi) & (s_hi > s_lo)
    return o, d, s_lo, np.where(ok, s_hi - s_lo, 0.0), ok


def _depth_sigma(o: np.ndarray, s_best: np.ndarray, d: np.ndarray, model, sets, amplitude: np.ndarray,
                 noise: np.ndarray) -> np.ndarray:
    """(P,) each pixel's depth sigma, metres: each fringe set's phase noise (noise over its modulation amplitude,
    ``amplitude`` (S, P) and ``noise`` (P,) in radiance) over its phase's rate along the ray (``o + s d``) at
    ``s_best``, combined over the sets, with :data:`MODEL_SIGMA_M` and :data:`MIN_SIGMA_M`."""
    P = len(s_best)
    pts = o + (s_best[:, None] + np.array([-0.5, 0.5])[None] * COARSE_STEP_M)[..., None] * d[:, None, :]
    pr = predicted_phasors(pts.reshape(-1, 3), model, sets).reshape(len(sets), P, 2)
    rate = np.angle(pr[..., 1] * np.conj(pr[..., 0])) / COARSE_STEP_M          # (S, P) radians per metre
    with np.errstate(divide="ignore", invalid="ignore"):
        sig_phase = noise[None] / (np.sqrt(2.0) * amplitude)
        info = np.nansum(np.where(np.isfinite(sig_phase) & (sig_phase > 0), np.square(rate / sig_phase), 0.0), 0)
        sig = np.where(info > 0, 1.0 / np.sqrt(info), np.inf)
    return np.sqrt(np.square(sig) + MODEL_SIGMA_M ** 2 + MIN_SIGMA_M ** 2)


def decode_structured_light(images: np.ndarray, model, view, sets: tuple[FringeSet, ...] = FRINGE_SETS) -> ViewDepth:
    """Each view pixel's real depth from its photographs of the fringes (see the module's docstring).

    Args:
        images: (S * SHIFTS, H, W) the view camera's grey radiance under each pattern of
            :func:`structured_light_patterns` (its order).
        model: the calibrated rig model.
        view: the view camera.
        sets: the fringe sets, as projected.

    Returns:
        :class:`~lftransfer.real_depth.lightfield.ViewDepth` (source ``"structured_light"``): distance along each
        pixel's ray, NaN where the coarse fringes modulate less than :data:`MIN_MODULATION` or less than
        :data:`MIN_SNR` times the images' noise (estimated from the four steps' residual), where the best match is
        at the end of the searched range, or where the model explains the pixel's fringes there worse than
        :data:`MIN_FIT` (light that reached the surface after a bounce off another); sigma from the fringes' noise
        through the phase's rate along the ray, combined with :data:`MODEL_SIGMA_M`.
    """
    n = len(sets)
    if images.shape[0] != n * SHIFTS:
        raise ValueError(f"structured light: expected {n * SHIFTS} images for {n} fringe sets, got {images.shape[0]}")
    h, w = images.shape[1:]
    obs, mean, noise = _observed(images, n)
    coarse = [i for i, s in enumerate(sets) if s.period_m == max(t.period_m for t in sets)]
    modulation = np.abs(obs[coarse]).min(0)
    amplitude = (np.abs(obs[coarse]) * mean[coarse]).min(0)                   # b of a + b cos, radiance
    valid = (modulation > MIN_MODULATION) & (mean.min(0) > 0) & (amplitude > MIN_SNR * noise)
    ys, xs = np.nonzero(valid)
    depth = np.full((h, w), np.nan, np.float32)
    sigma = np.full((h, w), np.nan, np.float32)
    if len(ys) == 0:
        return ViewDepth(depth, sigma, "structured_light")
    o, d, s_lo, span, ok = _searched_stretch(view, model, xs, ys)
    P = len(ys)
    ob = obs[:, ys, xs]                                       # (S, P)

    def sweep(centre: np.ndarray, half: np.ndarray, steps: int, which: list[int]) -> tuple[np.ndarray, np.ndarray]:
        """Scores of ``steps`` distances across centre +- half along each ray, for the sets ``which``: (P, steps)
        distances and scores."""
        grid = centre[:, None] + np.linspace(-1.0, 1.0, steps)[None] * half[:, None]
        pts = o + grid[..., None] * d[:, None, :]
        pred = predicted_phasors(pts.reshape(-1, 3), model, tuple(sets[i] for i in which)).reshape(len(which), P,
                                                                                                   steps)
        return grid, _score(pred, ob[which][:, :, None])

    rows = np.arange(P)
    # 1. the coarse fringes alone (one candidate over the whole stretch), every COARSE_SEARCH_M
    n1 = int(np.ceil(span.max() / COARSE_SEARCH_M)) + 1
    grid, sc = sweep(s_lo + span / 2, span / 2, n1, coarse)
    best = np.argmax(sc, axis=1)
    inside = ok & (best > 0) & (best < n1 - 1)
    step1 = span / max(n1 - 1, 1)
    # 2. every set, every COARSE_STEP_M across two coarse steps either side
    n2 = int(np.ceil(4 * step1.max() / COARSE_STEP_M)) + 1
    grid, sc = sweep(grid[rows, best], 2 * step1, n2, list(range(n)))
    best = np.argmax(sc, axis=1)
    step = grid[:, 1] - grid[:, 0]
    # 3. FINE_STEPS samples across one step either side, then a parabola through the best three
    fine, fs = sweep(grid[rows, best], step, FINE_STEPS, list(range(n)))
    b = np.clip(np.argmax(fs, axis=1), 1, FINE_STEPS - 2)
    y0, y1, y2 = fs[rows, b - 1], fs[rows, b], fs[rows, b + 1]
    with np.errstate(divide="ignore", invalid="ignore"):      # -inf: a candidate no lenslet lights
        curv = y0 - 2 * y1 + y2
        shift = np.where(curv < 0, 0.5 * (y0 - y2) / curv, 0.0)
    s_best = fine[rows, b] + np.clip(shift, -1.0, 1.0) * (fine[:, 1] - fine[:, 0])
    sig = _depth_sigma(o, s_best, d, model, sets, np.abs(ob) * mean[:, ys, xs], noise[ys, xs])
    # how well the model explains the pixel's fringes at its best distance (cosine of the phasors, 1: exactly):
    # light that reaches a surface after a bounce off another carries the coarse fringes but blurs the fine ones
    mid = o + s_best[:, None] * d
    best_pred = predicted_phasors(mid, model, sets)
    fit = _score(best_pred, ob) / np.maximum(np.sqrt(np.square(np.abs(ob)).sum(0)), 1e-12)
    inside &= fit >= MIN_FIT
    depth[ys[inside], xs[inside]] = s_best[inside]
    sigma[ys[inside], xs[inside]] = sig[inside]
    return ViewDepth(depth, sigma, "structured_light")
