"""The result of the lenslet calibration: detected centres, their lattice indices and the fitted lattice model."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lftransfer.calibration.lenslets.common import lattice_coordinates
from lftransfer.calibration.lenslets.model import _Model, _model_apply, _model_inverse


@dataclass
class LatticeFit:
    """Detected lenslet centres and the lattice fitted to them.

    Attributes:
        lattice: ``"hex"`` or ``"rect"``.
        centres: ``(N, 2) float64`` detected sub-pixel spot centres, pixels (x = col, y = row; origin at the
            centre of the top-left pixel), sorted row-major by lattice index.
        indices: ``(N, 2) int64`` lattice indices ``(row, col)`` of ``centres`` (see the module's conventions).
        homography: ``(3, 3) float64`` map from ideal lattice coordinates ``(u, v, 1)`` (unit pitch, see
            :func:`lattice_coordinates`) to undistorted pixels: the homography part of the lattice model (see
            :meth:`predicted`), fitted with ``distortion`` by least squares to all ``centres``. With no
            distortion (``distortion == 0``) it is the least-squares homography of the lattice.
        residuals: ``(N, 2) float64`` detected minus fitted lattice position (:meth:`predicted`), pixels.
        rms_px: RMS length of ``residuals``, pixels: the residual of the lattice model (homography + radial
            distortion, or the homography alone where the distortion was not significant).
        pitch_px: lenslet spacing along a row at the image centre (local derivative of the lattice model),
            pixels.
        rotation_deg: direction of the rows at the image centre, degrees counter-clockwise as seen on screen
            (image y points down); the rows are the lattice direction closest to the image x axis, so it lies
            within about +-30 deg (hex) or +-45 deg (rect). For a camera that faces the array squarely it has
            the sign of ``LensArray.rotation``.
        origin: ``(2,) float64`` pixel position of lattice index ``(0, 0)`` (from the lattice model).
        image_shape: ``(H, W)`` of the image.
        spot_sigma_px: spots: estimated standard deviation of the spots' blur, pixels; white images: radius of
            the centroid window (half the pitch), pixels.
        rejected: detections dropped by the lattice fit (off the lattice, or a second spot on one node).
        expected_shape: ``(rows, cols)`` of the array if it was given, else None.
        distortion: ``(2,) float64`` radial distortion ``(k1, k2)`` of the lattice model (zeros: none
            significant); ``k1 < 0`` barrel, ``k1 > 0`` pincushion.
        distortion_centre: ``(2,) float64`` centre ``c`` of the radial distortion, pixels (default: the
            image centre).
        distortion_scale: ``s``, the radius (pixels) that normalises ``rho`` (default: the image's
            half-diagonal, ``hypot(H - 1, W - 1) / 2``).
        homography_rms_px: RMS residual of the least-squares homography alone through the same ``centres``
            (equal to ``rms_px`` when ``distortion`` is zero; much larger than it on a distorted image).
        kind: ``"spots"`` or ``"white"``, the kind of image the centres come from.
    """

    lattice: str
    centres: np.ndarray
    indices: np.ndarray
    homography: np.ndarray
    residuals: np.ndarray
    rms_px: float
    pitch_px: float
    rotation_deg: float
    origin: np.ndarray
    image_shape: tuple[int, int]
    spot_sigma_px: float
    rejected: int = 0
    expected_shape: tuple[int, int] | None = None
    distortion: np.ndarray = field(default_factory=lambda: np.zeros(2))
    distortion_centre: np.ndarray | None = None
    distortion_scale: float = 0.0
    homography_rms_px: float | None = None
    kind: str = "spots"

    def __post_init__(self) -> None:
        h, w = self.image_shape
        self.distortion = np.asarray(self.distortion, dtype=np.float64).reshape(2)
        if self.distortion_centre is None:
            self.distortion_centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
        self.distortion_centre = np.asarray(self.distortion_centre, dtype=np.float64).reshape(2)
        if not self.distortion_scale > 0:
            self.distortion_scale = max(0.5 * math.hypot(h - 1, w - 1), 1.0)
        if self.homography_rms_px is None:
            self.homography_rms_px = self.rms_px

    @property
    def _model(self) -> _Model:
        return _Model(self.homography, self.distortion, self.distortion_centre, float(self.distortion_scale))

    def predicted(self, indices: np.ndarray) -> np.ndarray:
        """Fitted lattice positions of lattice indices (the lattice model of the module's docstring).

        Args:
            indices: ``(N, 2)`` integer ``(row, col)`` lattice indices (any, also of lenslets not detected).

        Returns:
            ``(N, 2) float64`` pixels (x, y): ``homography``, then the radial ``distortion`` about
            ``distortion_centre``.
        """
        return _model_apply(self._model, lattice_coordinates(indices, self.lattice))

    def to_lattice(self, points: np.ndarray) -> np.ndarray:
        """Ideal lattice coordinates of pixel positions (the inverse of the lattice model).

        Args:
            points: ``(N, 2)`` pixels (x, y).

        Returns:
            ``(N, 2) float64`` ideal ``(u, v)`` (unit pitch, see :func:`lattice_coordinates`).
        """
        return _model_inverse(self._model, np.asarray(points, dtype=np.float64).reshape(-1, 2))

    @property
    def max_residual_px(self) -> float:
        """Largest residual length, pixels."""
        return float(np.max(np.linalg.norm(self.residuals, axis=1))) if len(self.residuals) else 0.0

    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, cols)`` spanned by the detected indices (``max + 1``)."""
        return int(self.indices[:, 0].max()) + 1, int(self.indices[:, 1].max()) + 1

    def summary(self) -> str:
        """Human-readable multi-line description of the fit (lattice, counts, pitch, rotation, residuals)."""
        rows, cols = self.shape
        count = f"{len(self.centres)} lenslets in {rows} rows x {cols} columns"
        if self.expected_shape is not None:
            er, ec = self.expected_shape
            count += f" (array: {er} x {ec} = {er * ec})"
        ox, oy = self.origin
        size = (f"spot sigma {self.spot_sigma_px:.2f} px" if self.kind == "spots"
                else f"white image, centroid window radius {self.spot_sigma_px:.2f} px")
        if np.any(self.distortion != 0):
            k1, k2 = self.distortion
            cx, cy = self.distortion_centre
            model = (f"lattice model: homography + radial distortion k1 {k1:+.5f}, k2 {k2:+.5f} about "
                     f"({cx:.1f}, {cy:.1f}) px (rho = radius / {self.distortion_scale:.1f} px); homography "
                     f"alone: RMS {self.homography_rms_px:.4f} px")
        else:
            model = "lattice model: homography (no significant radial distortion)"
        return "\n".join([
            f"lattice: {self.lattice}, {count}",
            f"pitch: {self.pitch_px:.3f} px along rows at the image centre; "
            f"rotation: {self.rotation_deg:+.3f} deg (counter-clockwise)",
            f"origin (row 0, col 0): ({ox:.3f}, {oy:.3f}) px; {size}",
            model,
            f"lattice fit residuals: RMS {self.rms_px:.4f} px, max {self.max_residual_px:.4f} px; "
            f"{self.rejected} detection(s) off the lattice dropped",
        ])
