"""The result of the radiometric calibration (:class:`Radiometry`), its vignetting map
(:class:`VignettingPolynomial`) and the distance of two responses (:func:`response_error`)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from lftransfer.lightfield import ResponseCurve


def response_error(a: ResponseCurve, b: ResponseCurve) -> float:
    """Largest difference of two responses' codes, as a fraction of full scale.

    Max over the three channels and 1001 linear values in [0, 1] of ``|a.encode(x) - b.encode(x)|``.
    """
    x = np.repeat(np.linspace(0.0, 1.0, 1001)[:, None], 3, axis=1)
    return float(np.max(np.abs(a.encode(x) - b.encode(x))))


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
