"""Radiometric calibration of the light field interface (paper, section 4.2, its "future work").

Geometry (lens array pose, lenslet intrinsics, projector-camera mapping) comes from the other calibration steps
and is passed in as a :class:`~lftransfer.rig.model.RigModel`; this module finds the device radiometry that goes
into the model's :class:`~lftransfer.lightfield.CameraModel` and :class:`~lftransfer.lightfield.ProjectorModel`:

- camera: response (a power law per channel, ``code = signal^(1/gamma)``), vignetting, exposure;
- projector: response (``drive = code^gamma`` per channel), colour cross-talk ``C`` (3 x 3), black level ``b``
  and brightness ``max_radiance``: a pixel with codes n emits ``max_radiance * (b + C @ (n / levels)^gamma)``.

It uses only what the pipeline may know: the rig file's nominal values, the (geometrically calibrated) model
passed in, the scene's view camera, and images from two calibration actions of the rig:
a :class:`~lftransfer.rig.requests.FocalPlaneDiffuser` set-up (a diffuser at the lenslets' focal plane: the LF
camera sees the projector's pixels directly; LF captures with exposure bracketing) and a
:class:`~lftransfer.rig.requests.Board` set-up (the view camera's absolute radiance image of a grey diffuse board of
known albedo lit through the array by the projector; the view camera is the radiometric reference).

Procedure (:func:`calibrate_radiometry`):

a. **Camera response.** The projector shows a grey horizontal ramp of codes (dark to bright); the focal plane
   is captured at several exposure times ``e`` (factors of 2 apart). A pixel's code is
   ``c = (s e)^(1/gamma)``, so ``log c`` against ``log e`` has slope ``1/gamma`` wherever the pixel is neither
   dark nor saturated (codes in [0.04, 0.95] of full scale are used). Per pixel and channel a weighted
   regression gives a slope; the median over pixels, then the pooled slope over the pixels near it (outliers
   out), gives ``gamma`` per channel.
b. **Camera vignetting.** A uniform full-code projector image on the diffuser (exposure chosen from (a) so that
   nothing saturates) is linearised with (a); each channel is divided by its median, the channels are averaged,
   and a 2-D polynomial (degree 4 in normalised pixel coordinates) is fitted by least squares with outlier
   rejection. The map is the polynomial normalised to 1 at its maximum over the fitted area (its absolute scale
   belongs to the exposure); pixels outside the area the projector covers get the polynomial's value too. The
   flat field holds the projector's own non-uniformity (and the diffuser's) as well, if any: the simulated rig
   has none; on hardware it would show up as vignetting.
c. **Projector response, black level, cross-talk.** Uniform projector images at the same exposure: all channels
   at code 0 (black, at a longer exposure for precision), then per projector channel j a ramp of levels with the
   other channels at 0. The camera signal, linearised by (a), divided by the vignetting and averaged over a
   central region, is ``S(n, j) = G (b + C[:, j] r_j(n))`` with an unknown common gain G (diffuser x
   exposure x max_radiance). With ``D = S - S(black) = G C[:, j] r_j(n)``, a separable least-squares fit per
   projector channel gives ``gamma_j`` (``r_j(n) = (n / levels)^gamma_j``) and the column ``G C[:, j]``. C is
   known up to scale only: it is normalised so that the mean of its diagonal is 1, and the black level is
   expressed on that same scale (``b = S(black) / s`` with s the mean diagonal of ``G C``).
d. **Absolute scale.** (i) Projector: a board asked for with a uniform full-code projector image, the board
   (0.2 m square, albedo 0.8) on the array's axis 0.1-0.2 m in front of it (the farthest of a few distances
   whose centre the view camera sees well), turned half-way between the array and the view camera. The same
   view camera pixels around the board centre are rendered with our own renderer
   (:class:`~lftransfer.render.renderer.HalfSpaceRenderer`, the board as a rectangle) lit by the light field
   that the calibrated projector model emits at ``max_radiance = 1`` (:class:`~lftransfer.render.lights.
   LightFieldLight`, area model, as the simulated rig does). The ratio of measured to predicted radiance is
   ``max_radiance``. (ii) Camera exposure: no available action measures it (the focal-plane captures give only
   the product diffuser transmission x exposure, kept in the diagnostics as ``exposure_times_diffuser``), so it
   stays at the value of the model passed in (the rig file's nominal value).

Everything is vectorised; the per-pixel work runs on a strided subset of pixels where a full image is not
needed. Progress goes to an optional callback, one call per capture group.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Callable

import cv2
import numpy as np

from lftransfer.calibration.pose import CHART, PoseError, chart_pose
from lftransfer.lightfield import ResponseCurve
from lftransfer.optics.geometry import project
from lftransfer.render.shapes import board_shapes, lens_array_absorber
from lftransfer.rig.base import Rig
from lftransfer.rig.requests import Board, FocalPlaneDiffuser, LFCapture, ViewCapture

__all__ = ["Radiometry", "RadiometryError", "VignettingPolynomial", "calibrate_radiometry", "response_error",
           "BOARD_DISTANCES", "BOARD_ALBEDO"]

Progress = Callable[[str], None]

BOARD_DISTANCES = (0.2, 0.15, 0.12, 0.1)    # metres in front of the array centre, the first the view sees well
BOARD_SIZE = (0.2, 0.2)
BOARD_ALBEDO = 0.8
BOARD_CHART = CHART               # its printed chessboard (the pose boards' own), which tells where it really stands

_DARK, _BRIGHT = 0.04, 0.95         # usable normalised camera codes for the response fit
_SATURATED = 0.97


class RadiometryError(RuntimeError):
    """A radiometric calibration step could not be done (the message says which and why)."""


def response_error(a: ResponseCurve, b: ResponseCurve) -> float:
    """Largest difference of two responses' codes, as a fraction of full scale.

    Max over the three channels and 1001 linear values in [0, 1] of ``|a.encode(x) - b.encode(x)|``.
    """
    x = np.repeat(np.linspace(0.0, 1.0, 1001)[:, None], 3, axis=1)
    return float(np.max(np.abs(a.encode(x) - b.encode(x))))


# ---- vignetting polynomial ---------------------------------------------------------------------------------
def _terms(degree: int) -> list[tuple[int, int]]:
    """Exponents (i, j) of x^i y^j with i + j <= degree, in a fixed order."""
    return [(i, d - i) for d in range(degree + 1) for i in range(d, -1, -1)]


def _norm_coords(index: np.ndarray, size: int) -> np.ndarray:
    half = max((size - 1) / 2.0, 0.5)
    return (np.asarray(index, np.float64) - (size - 1) / 2.0) / half


@dataclass(frozen=True)
class VignettingPolynomial:
    """A smooth relative-sensitivity map: ``sum_t coeffs[t] x^i_t y^j_t`` over normalised pixel coordinates.

    ``x = (col - (W - 1) / 2) / ((W - 1) / 2)``, ``y`` likewise for rows (both in [-1, 1]); terms in the order
    of increasing total degree, x's power first descending (``1, x, y, x^2, xy, y^2, ...``).

    Attributes:
        degree: total degree.
        coeffs: coefficients, one per term.
        shape: (H, W) of the camera image.
        floor: the map is clipped below at this value (far extrapolations of the polynomial).
    """

    degree: int
    coeffs: tuple[float, ...]
    shape: tuple[int, int]
    floor: float = 0.05

    def __post_init__(self) -> None:
        object.__setattr__(self, "coeffs", tuple(float(c) for c in self.coeffs))
        object.__setattr__(self, "shape", (int(self.shape[0]), int(self.shape[1])))
        if len(self.coeffs) != len(_terms(self.degree)):
            raise ValueError(f"a degree-{self.degree} polynomial has {len(_terms(self.degree))} coefficients, "
                             f"got {len(self.coeffs)}")

    @staticmethod
    def design(x: np.ndarray, y: np.ndarray, degree: int) -> np.ndarray:
        """(N, T) design matrix of the terms at normalised coordinates."""
        return np.stack([x ** i * y ** j for i, j in _terms(degree)], axis=1)

    def evaluate(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """The map at pixel positions (any shape, float64), clipped below at ``floor``."""
        h, w = self.shape
        x, y = _norm_coords(cols, w).ravel(), _norm_coords(rows, h).ravel()
        v = self.design(x, y, self.degree) @ np.asarray(self.coeffs)
        return np.maximum(v, self.floor).reshape(np.shape(rows))

    def map(self) -> np.ndarray:
        """``(H, W) float32`` map over the whole image (separable evaluation, no per-pixel design matrix)."""
        h, w = self.shape
        d = self.degree
        vx = _norm_coords(np.arange(w), w)[:, None] ** np.arange(d + 1)[None, :]     # (W, d+1)
        vy = _norm_coords(np.arange(h), h)[:, None] ** np.arange(d + 1)[None, :]     # (H, d+1)
        cm = np.zeros((d + 1, d + 1))
        for c, (i, j) in zip(self.coeffs, _terms(d)):
            cm[j, i] = c
        return np.maximum(vy @ cm @ vx.T, self.floor).astype(np.float32)

    def to_json(self) -> dict:
        return {"degree": self.degree, "coeffs": list(self.coeffs), "shape": list(self.shape), "floor": self.floor}

    @classmethod
    def from_json(cls, data: dict) -> "VignettingPolynomial":
        return cls(degree=int(data["degree"]), coeffs=tuple(data["coeffs"]), shape=tuple(data["shape"]),
                   floor=float(data.get("floor", 0.05)))


# ---- result ------------------------------------------------------------------------------------------------
@dataclass(eq=False)
class Radiometry:
    """Result of :func:`calibrate_radiometry`.

    Attributes:
        camera_gamma: (3,) camera response exponents (``code = signal^(1/gamma)``).
        camera_exposure: normalised camera signal per unit radiance (sr m^2 W^-1).
        vignetting_poly: the camera's relative sensitivity, 1 at its maximum (:attr:`vignetting` is its map).
        projector_gamma: (3,) projector response exponents (``drive = code^gamma``).
        cross_talk: (3, 3) projector colour mixing, mean of the diagonal 1.
        black_level: (3,) light at code 0, fraction of ``max_radiance``.
        max_radiance: projector brightness, W m^-2 sr^-1 (scale of ``cross_talk`` and ``black_level``).
        diagnostics: JSON-ready raw measurements for reports and plots (see :func:`calibrate_radiometry`).
    """

    camera_gamma: np.ndarray
    camera_exposure: float
    vignetting_poly: VignettingPolynomial
    projector_gamma: np.ndarray
    cross_talk: np.ndarray
    black_level: np.ndarray
    max_radiance: float
    diagnostics: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.camera_gamma = np.asarray(self.camera_gamma, np.float64).reshape(3)
        self.projector_gamma = np.asarray(self.projector_gamma, np.float64).reshape(3)
        self.cross_talk = np.asarray(self.cross_talk, np.float64).reshape(3, 3)
        self.black_level = np.asarray(self.black_level, np.float64).reshape(3)
        self.camera_exposure = float(self.camera_exposure)
        self.max_radiance = float(self.max_radiance)

    @cached_property
    def vignetting(self) -> np.ndarray:
        """``(H, W) float32`` camera vignetting map."""
        return self.vignetting_poly.map()

    @property
    def camera_response(self) -> ResponseCurve:
        return ResponseCurve(tuple(self.camera_gamma))

    @property
    def projector_response(self) -> ResponseCurve:
        return ResponseCurve(tuple(self.projector_gamma))

    def apply(self, model):
        """The model (``RigModel``) with this radiometry in its camera and projector; geometry unchanged."""
        cam = model.camera
        if (cam.device.height, cam.device.width) != self.vignetting_poly.shape:
            raise ValueError(f"vignetting is for {self.vignetting_poly.shape} images, the model's camera is "
                             f"{(cam.device.height, cam.device.width)}")
        camera = replace(cam, response=self.camera_response, exposure=self.camera_exposure,
                         vignetting=self.vignetting.copy())
        projector = replace(model.projector, response=self.projector_response, max_radiance=self.max_radiance,
                            cross_talk=self.cross_talk.copy(), black_level=tuple(self.black_level.tolist()))
        return replace(model, camera=camera, projector=projector)

    def to_json(self) -> dict:
        """JSON-ready dict (numbers as lists; the vignetting as polynomial coefficients and image shape)."""
        return {
            "camera_gamma": self.camera_gamma.tolist(),
            "camera_exposure": self.camera_exposure,
            "vignetting": self.vignetting_poly.to_json(),
            "projector_gamma": self.projector_gamma.tolist(),
            "cross_talk": self.cross_talk.tolist(),
            "black_level": self.black_level.tolist(),
            "max_radiance": self.max_radiance,
            "diagnostics": self.diagnostics,
        }

    @classmethod
    def from_json(cls, data: dict) -> "Radiometry":
        return cls(camera_gamma=data["camera_gamma"], camera_exposure=data["camera_exposure"],
                   vignetting_poly=VignettingPolynomial.from_json(data["vignetting"]),
                   projector_gamma=data["projector_gamma"], cross_talk=data["cross_talk"],
                   black_level=data["black_level"], max_radiance=data["max_radiance"],
                   diagnostics=dict(data.get("diagnostics", {})))


# ---- the steps -----------------------------------------------------------------------------------------------
def _stride(h: int, w: int, target: int) -> int:
    return max(1, int(math.ceil(math.sqrt(h * w / target))))


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


def _board_pose(scene, model):
    """Where the board is asked for: centre, normal (rig frame, the best guess of the model's frame before the
    pose step), the view camera in the model's array frame and the board centre's view pixel.

    The centre lies on the array's axis at the first of :data:`BOARD_DISTANCES` whose image falls well inside
    the view (15 % from every border); the normal is half-way between -z (towards the array, which lights it)
    and the direction to the view camera.
    """
    from lftransfer.calibration.pose import board_pattern
    from lftransfer.scenes.frame import scene_in_frame

    view = scene_in_frame(scene, model.world_to_array()).view
    vw, vh = view.resolution
    for z in BOARD_DISTANCES:
        board = board_pattern(scene.view, z)
        centre, normal = tuple(board.centre.tolist()), board.normal
        px = project(view, board.centre[None])[0]
        if 0.15 * vw <= px[0] <= 0.85 * vw and 0.15 * vh <= px[1] <= 0.85 * vh:
            return centre, normal, view, tuple(int(round(v)) for v in px)
    raise RadiometryError(f"brightness: no board position {BOARD_DISTANCES} m in front of the array centre "
                          "is seen well by the view camera")


def _window_rays(sensor, width: int, height: int, xs: np.ndarray, ys: np.ndarray, spp: int, seed: int):
    """Primary rays (jittered, ``spp`` per pixel, pixel-major) through the given view camera pixels."""
    from lftransfer.backend import mitsuba

    mi = mitsuba()
    rng = np.random.default_rng(seed)
    n = len(xs)
    px = (xs[:, None] + rng.random((n, spp))) / width
    py = (ys[:, None] + rng.random((n, spp))) / height
    ray, _ = sensor.sample_ray(mi.Float(0.0), mi.Float(0.5),
                               mi.Point2f(px.ravel().astype(np.float32), py.ravel().astype(np.float32)),
                               mi.Point2f(0.5, 0.5))
    centre = np.array(sensor.world_transform().translation(), dtype=np.float32).ravel()[:3]
    d = np.ascontiguousarray(np.array(ray.d, dtype=np.float32).T)
    return np.ascontiguousarray(np.broadcast_to(centre, (n * spp, 3))), d


def _held_board(image: np.ndarray, view, asked_normal) -> np.ndarray:
    """(4, 4) ``to_world`` of the board rectangle where the view camera sees it stand (its printed chart's pose),
    facing the side it was asked to face."""
    try:
        m, _ = chart_pose(image, BOARD_CHART, view)
    except PoseError as exc:
        raise RadiometryError(f"brightness: {exc}") from None
    if m[:3, 2] @ np.asarray(asked_normal, np.float64) < 0:       # keep a right-handed frame facing the array
        m[:3, 1:3] *= -1
    m[:3, 0] *= BOARD_SIZE[0] / 2
    m[:3, 1] *= BOARD_SIZE[1] / 2
    return m


def _predict_board(model, scene, projector, image: np.ndarray, to_world: np.ndarray,
                   pixels: tuple[np.ndarray, np.ndarray], *, angular_samples: int, spp: int, aperture_samples: int,
                   seed: int = 0):
    """Our own render of the board (``to_world``: its rectangle, printed chart included) at view pixels, lit by
    ``projector`` showing ``image``."""
    from lftransfer.backend import mitsuba
    from lftransfer.lightfield import LightFieldEncoder
    from lftransfer.render.camera import sensor_dict
    from lftransfer.render.lights import LightFieldLight
    from lftransfer.render.renderer import HalfSpaceRenderer
    from lftransfer.scenes.frame import scene_in_frame

    mi = mitsuba()
    array = model.array
    view = scene_in_frame(scene, model.world_to_array()).view
    shapes = board_shapes(to_world, BOARD_ALBEDO, BOARD_CHART)
    renderer = HalfSpaceRenderer([], extra_shapes={**shapes, "lens_array_absorber": lens_array_absorber(array)},
                                 max_depth=1)
    encoder = LightFieldEncoder(array, projector, angular_samples, angular_samples)
    lf = encoder.codec.image_to_lightfield(encoder.emitted(image))
    light = LightFieldLight(lf, side="real", model="area", aperture_samples=aperture_samples, seed=seed + 3)
    w, h = view.resolution
    sensor = mi.load_dict(sensor_dict(view.origin, view.target, view.up, view.fov_deg, w, h))
    xs, ys = pixels
    o, d = _window_rays(sensor, w, h, xs.astype(np.float64), ys.astype(np.float64), spp, seed)
    radiance, hit, _ = renderer.render_rays(o, d, [light], seed=seed)
    return radiance.reshape(len(xs), spp, 3).mean(1), hit.reshape(len(xs), spp).all(1), view


# ---- the stages of calibrate_radiometry -------------------------------------------------------------------------
@dataclass
class _FocalPlane:
    """The focal-plane diffuser captures: projector images of uniform or ramp codes, LF captures as normalised codes.

    Attributes:
        rig: the rig (its set-up is the :class:`~lftransfer.rig.requests.FocalPlaneDiffuser` while captured).
        shape: ``(H, W)`` of the projector, pixels.
        levels: the projector's full-scale code; ``dtype`` its images' dtype.
        camera_levels: the LF camera's full-scale code.
        captures: LF captures taken so far.
    """

    rig: Rig
    shape: tuple[int, int]
    levels: int
    dtype: np.dtype
    camera_levels: float
    captures: int = 0

    def capture(self, image: np.ndarray, e: float) -> np.ndarray:
        """Project ``image`` and capture at exposure scale ``e``: ``(H, W, 3) float32`` codes in [0, 1]."""
        self.captures += 1
        self.rig.project(image)
        codes = self.rig.capture_lf(LFCapture(exposure_scale=float(e))).codes
        return codes.astype(np.float32) / np.float32(self.camera_levels)

    def uniform(self, codes) -> np.ndarray:
        """``(H, W, 3)`` projector image of the same codes (3,) everywhere."""
        prj_h, prj_w = self.shape
        return np.broadcast_to(np.asarray(codes, self.dtype), (prj_h, prj_w, 3)).copy()


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


@dataclass
class _BoardMeasurement:
    """Step (d): the projector's absolute brightness from a board seen by the view camera.

    Attributes:
        max_radiance: measured over predicted radiance (at ``max_radiance = 1``), all channels pooled.
        per_channel: ``(3,)`` the same ratio per channel.
        measured_mean: ``(3,)`` mean measured radiance of the pixels used.
        pixels: view pixels used (the board hit by every ray of our render, not dark).
        held: ``(4, 4)`` ``to_world`` of the board where it really stood (its printed chart's pose).
        centre_pixel: ``(x, y)`` view pixel of the held board's centre.
    """

    max_radiance: float
    per_channel: np.ndarray
    measured_mean: np.ndarray
    pixels: int
    held: np.ndarray
    centre_pixel: tuple[int, int]


def _measure_brightness(rig: Rig, model, scene, projector_fit: _ProjectorFit, white: np.ndarray, *,
                        board_spp: int | None, predict_spp: int, angular_samples: int, seed: int,
                        say: Progress) -> _BoardMeasurement:
    """Step (d, i): the board lit by the full-code projector image, measured and predicted by our own render.

    The view pixels around the held board's centre (a square of half-width 4 % of the view's width, halved up
    to 3 times until our render's rays all hit the board) are rendered lit by the calibrated projector model at
    ``max_radiance = 1``.

    Returns:
        The ratio of measured to predicted radiance and the board measurement.

    Raises:
        RadiometryError: no board position is seen well, its chart is not found, its centre projects outside
            the view, or our render of it is dark.
    """
    say("projector brightness: board in front of the array (view camera)")
    centre, normal, view, _ = _board_pose(scene, model)
    rig.setup(Board(centre=centre, normal=tuple(normal), size=BOARD_SIZE, albedo=BOARD_ALBEDO, chart=BOARD_CHART))
    rig.project(white)
    measured = rig.capture_view(ViewCapture(quality=board_spp)).radiance
    # where the board really stands (held by hand): from the chessboard printed on it
    held = _held_board(measured, scene.view, normal)
    cx, cy = (int(round(v)) for v in project(view, held[:3, 3][None])[0])
    projector = replace(model.projector, response=ResponseCurve(tuple(projector_fit.gamma)), max_radiance=1.0,
                        cross_talk=projector_fit.cross_talk, black_level=tuple(projector_fit.black_level.tolist()))
    vw, vh = view.resolution
    half = max(3, int(round(0.04 * vw)))
    say("projector brightness: our own render of the board")
    for _ in range(4):
        ys, xs = np.mgrid[max(cy - half, 0):min(cy + half + 1, vh), max(cx - half, 0):min(cx + half + 1, vw)]
        xs, ys = xs.ravel(), ys.ravel()
        if len(xs) == 0:
            raise RadiometryError(f"brightness: the board centre projects outside the view camera ({cx}, {cy})")
        predicted, hit, _ = _predict_board(model, scene, projector, white, held, (xs, ys),
                                           angular_samples=angular_samples, spp=predict_spp,
                                           aperture_samples=8, seed=seed)
        if hit.all() or half <= 3:
            break
        half = max(3, half // 2)
    use = hit & (predicted.sum(1) > 0)
    if use.sum() < 9:
        raise RadiometryError("brightness: our render of the board is dark around its centre")
    meas = measured[ys[use], xs[use]].astype(np.float64)
    pred = predicted[use].astype(np.float64)
    return _BoardMeasurement(max_radiance=float(meas.sum() / pred.sum()), per_channel=meas.sum(0) / pred.sum(0),
                             measured_mean=meas.mean(0), pixels=int(use.sum()), held=held, centre_pixel=(cx, cy))


def _diagnostics(response: _CameraResponse, flat: _FlatField, projector_fit: _ProjectorFit,
                 board: _BoardMeasurement, focal_plane_captures: int, timings: dict[str, float]) -> dict:
    """The measurements behind the result, JSON-ready (see :func:`calibrate_radiometry`)."""
    cx, cy = board.centre_pixel
    return {
        "camera_response_samples": response.diag["samples"],
        "camera_response_pixels": response.diag["pixels"],
        "exposure_scales": response.scales.tolist(),
        "flat_exposure_scale": flat.exposure,
        "black_exposure_scale": projector_fit.black_exposure,
        "vignetting_fit": flat.diag,
        "projector_levels": projector_fit.levels.tolist(),
        "projector_response_samples": projector_fit.response_samples,
        "projector_fit_rms": projector_fit.fit_rms,
        "black_signal": projector_fit.black.tolist(),
        "channel_signals": projector_fit.samples.tolist(),
        "board_pixels": board.pixels,
        "board_centre_m": board.held[:3, 3].tolist(),
        "board_centre_pixel": [int(cx), int(cy)],
        "board_ratio_per_channel": board.per_channel.tolist(),
        "board_measured_mean": board.measured_mean.tolist(),
        # focal-plane signal per unit exposure_scale and radiance = diffuser transmission x camera exposure
        "exposure_times_diffuser": projector_fit.scale / board.max_radiance,
        "camera_exposure_source": "model (no capture measures it)",
        "captures": {"focal_plane": focal_plane_captures, "board": 1},
        "timings_s": {k: round(v, 3) for k, v in timings.items()},
    }


def calibrate_radiometry(rig: Rig, model, scene, *, progress: Progress | None = None,
                         exposures: int = 5, projector_levels: int = 4, vignetting_degree: int = 4,
                         board_spp: int | None = None, predict_spp: int = 16, angular_samples: int = 64,
                         seed: int = 0) -> Radiometry:
    """Calibrate the camera's and the projector's radiometry from rig captures (module docstring: the steps).

    Args:
        rig: the rig; it is asked for the focal-plane diffuser (with exposure bracketing) and a grey board.
        model: the current ``RigModel`` (calibrated geometry; its bit depths and exposure are used).
        scene: the scene (``SceneConfig``): nominal rig file values and the view camera.
        progress: called with a message once per capture group.
        exposures: captures of the exposure bracket of step (a) (factors of 2 apart).
        projector_levels: uniform levels per projector channel in step (c).
        vignetting_degree: total degree of the vignetting polynomial.
        board_spp: view camera samples per pixel of the board capture (None: the rig's default).
        predict_spp: samples per pixel of our own render of the board.
        angular_samples: U = V of the light field that lights our own render of the board.
        seed: seed of the sampling in our own render and of the diagnostic subsets.

    Returns:
        Radiometry. ``diagnostics`` holds the camera response samples (per channel a list of (relative
        exposure x linear signal, normalised code)), the projector response samples (per channel a list of
        (normalised code, measured normalised drive)), fit residuals, the exposure scales used, the board
        measurement, ``exposure_times_diffuser`` and timings.
    """
    say = progress or (lambda message: None)
    rng = np.random.default_rng(seed)
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    fp = _FocalPlane(rig, tuple(rig.info.projector_shape), model.projector.levels, model.projector.dtype,
                     float(model.camera.levels))

    t = time.perf_counter()
    response = _measure_camera_response(fp, model, exposures, rng, say)                           # a.
    timings["camera_response"] = time.perf_counter() - t
    t = time.perf_counter()
    flat = _measure_vignetting(fp, response, vignetting_degree, say)                                # b.
    timings["vignetting"] = time.perf_counter() - t
    t = time.perf_counter()
    projector_fit = _measure_projector(fp, response, flat, projector_levels, say)                   # c.
    timings["projector"] = time.perf_counter() - t
    t = time.perf_counter()
    board = _measure_brightness(rig, model, scene, projector_fit, flat.white, board_spp=board_spp,   # d.
                                predict_spp=predict_spp, angular_samples=angular_samples, seed=seed, say=say)
    timings["brightness"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t_start

    return Radiometry(camera_gamma=response.gamma, camera_exposure=model.camera.exposure, vignetting_poly=flat.poly,
                      projector_gamma=projector_fit.gamma, cross_talk=projector_fit.cross_talk,
                      black_level=projector_fit.black_level, max_radiance=board.max_radiance,
                      diagnostics=_diagnostics(response, flat, projector_fit, board, fp.captures, timings))
