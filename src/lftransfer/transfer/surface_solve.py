"""The projection solved against the measured real surface (``projection = "solve"``; docs/architecture.md, "The
projection solved against the measured surface").

The projector can only add light, one radiance per direction over each lenslet's whole aperture. The light that
matters is the light arriving at the real surface, and the rig measures where that surface is
(:func:`~lftransfer.real_depth.measured_surface`: points, normals, a confidence per point). So the light field X the
projector is sent (above its black) is chosen to make the irradiance it gives each measured point equal to the
irradiance the synthetic objects send it:

    min over 0 <= X <= X_max of  sum_n c_n^2 (F X - T)_n^2,   entries landing on no point kept at the box light field

- F: irradiance at the measured points from a light field whose lenslets emit one radiance per direction over
  their aperture, read bilinearly between grid directions (as the projector's lenslets are), over a fixed set of
  ``aperture_samples`` stratified aperture points per lenslet, with the point's measured normal for the cosine and
  the measured depth for visibility (a point hidden from a lenslet's centre behind the measured surface gets nothing
  from it). F is a sparse matrix built once per depth.
- T: the synthetic objects' irradiance at the same points over the same aperture points: the renderer traces each
  aperture point's ray into the synthetic half-space (:attr:`SurfaceSolve.origins`, :attr:`~SurfaceSolve.directions`)
  and T is the same weighted sum of their radiance (:meth:`SurfaceSolve.target`). Where the projector could
  reproduce that light exactly, the fit is exact; where it cannot (an edge sharper than a lenslet's footprint,
  light beyond the window), it finds the closest it can send.
- X_max: each channel's radiance at its full drive (the model projector's emission); 0 off the data samples.
- c: each point's confidence.

The fit is the fidelity floor's solver (:func:`~lftransfer.transfer.solver.box_least_squares`, here FISTA with
gradient restart, two applications of F a step), started from the box light field. The encoder then sends X as it
sends any light field. Unlike the floor it knows nothing of the real objects' material and fits no reference: its
yardstick stays the floor (docs/architecture.md).

Linear: the synthetic light field carries its surface target (:class:`TargetedLightField`); sums and gains of it
(the bounce loop projects g Ls_n and, in the final frame, Ls_0 + ... + Ls_{N-1}) carry the same sums and gains of
the targets, and :class:`SolvingEncoder`, the synthetic side's encoder, solves when it is given one. A target
close to the last one solved (a live loop's next frame, or the same light at another gain) starts from the last
solution, and a solve stops once converged (:data:`TOLERANCE`): a still scene's frame takes one step.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from lftransfer.lightfield import LightField
from lftransfer.lightfield.devices import ProjectorDrive
from lftransfer.real_depth.surface import MeasuredSurface
from lftransfer.transfer.solver import RowBlocks, box_least_squares

__all__ = ["APERTURE_SAMPLES", "ITERATIONS", "SolveRecord", "SolvingEncoder", "SurfaceSolve", "TargetedLightField",
           "TOLERANCE", "VISIBILITY_TOLERANCE_M", "WARM_CHANGE", "WARM_ITERATIONS"]

APERTURE_SAMPLES = 32           # aperture points per lenslet of F and T
ITERATIONS = 30                 # steps from the box light field (a cold solve)
WARM_ITERATIONS = 1             # ... from the last solution, when the target changed little or in a live loop
WARM_CHANGE = 0.2               # "changed little": |T - T_last| below this fraction of |T|
TOLERANCE = 1e-3                # stop once a step's guaranteed decrease is below this fraction of the loss
HISTORY = 64                    # solves remembered (SurfaceSolve.history)
VISIBILITY_TOLERANCE_M = 0.004  # a point farther than the measured depth by more than this is hidden


@dataclass(eq=False)
class TargetedLightField(LightField):
    """A synthetic light field (the box light field: each entry the mean over its aperture) with the irradiance
    it should give the measured real surface (:meth:`SurfaceSolve.target`). Sums, differences and scalings apply
    to both, so a bounce's gain and the final frame's sum keep their targets.

    Attributes:
        target: (N, 3) float32 irradiance at the :class:`SurfaceSolve`'s points, W m^-2.
    """

    target: np.ndarray = field(default=None, repr=False)

    def _with(self, lf: LightField, target: np.ndarray) -> "TargetedLightField":
        return TargetedLightField(lf.data, lf.array, np.asarray(target, np.float32))

    def __add__(self, other):
        out = LightField.__add__(self, other)
        if out is NotImplemented:
            return out
        return self._with(out, self.target + other.target if isinstance(other, TargetedLightField) else self.target)

    def __radd__(self, other):
        if isinstance(other, LightField):        # LightField + TargetedLightField lands here first
            return self.__add__(other)
        return self._with(LightField.__radd__(self, other), self.target)

    def __sub__(self, other):
        out = LightField.__sub__(self, other)
        if out is NotImplemented:
            return out
        return self._with(out, self.target - other.target if isinstance(other, TargetedLightField) else self.target)

    def __neg__(self):
        return self._with(LightField.__neg__(self), -self.target)

    def __mul__(self, scalar: float):
        return self._with(LightField.__mul__(self, scalar), self.target * np.float32(scalar))

    __rmul__ = __mul__

    def __truediv__(self, scalar: float):
        return self._with(LightField.__truediv__(self, scalar), self.target / np.float32(scalar))

    def copy(self) -> "TargetedLightField":
        return self._with(LightField.copy(self), self.target.copy())


@dataclass(frozen=True)
class SolveRecord:
    """One solve (:attr:`SurfaceSolve.history`).

    Attributes:
        warm: started from the last solution (the target changed little) rather than from the box light field.
        iterations: the steps taken (fewer than asked where converged, :data:`TOLERANCE`).
        seconds: wall-clock time of the solve.
        loss_start, loss_end: the weighted squared misfit sum_n c_n^2 |F X - T|_n^2 of the start and (an upper
            bound of) the result, (W m^-2)^2.
    """

    warm: bool
    iterations: int
    seconds: float
    loss_start: float
    loss_end: float


class SurfaceSolve:
    """F, the target's rays and the solve for one measured surface and one projector model (module docstring).

    Args:
        surface: the measured real surface (array frame).
        encoder: the rig model's :class:`~lftransfer.lightfield.LightFieldEncoder` (``above_black``: the light
            field is light added to the projector's black).
        aperture_samples: aperture points per lenslet.
        seed: their stratification's seed.

    Attributes:
        origins, directions: (R, 3) float32 read-only rays whose synthetic radiance makes the target: from aperture
            points (z = 0) into the synthetic half-space (z < 0).
        points: N, the surface's points; rays: R.
        surface, encoder, seed: as given.
        landed: (K, V, U) bool read-only: the entries whose light lands on a measured point (the ones fitted).
        emission: M, (3, 3) float32: the model projector's radiance per unit drive (its colour cross-talk).
        history: the last :data:`HISTORY` solves (:class:`SolveRecord`).
        live: set by a live loop: every solve after the first starts from the last solution and takes at most
            :data:`WARM_ITERATIONS` steps, however much the target changed, so the solution converges over the
            frames rather than within one (a bounce loop's targets, which differ by bounce, start cold).
    """

    def __init__(self, surface: MeasuredSurface, encoder, *, aperture_samples: int = APERTURE_SAMPLES,
                 seed: int = 0) -> None:
        array, codec = encoder.array, encoder.codec
        U, V, K = codec.U, codec.V, array.K
        self.surface, self.encoder, self.seed = surface, encoder, seed
        if surface.depth.shape != (K, V, U):
            raise ValueError(f"the surface's depth has shape {surface.depth.shape}, the encoder's light field "
                             f"{(K, V, U)}")
        rows, cols, vals, ray_point, origins, directions, weights = self._geometry(surface, array, U, V,
                                                                                   aperture_samples, seed)
        N, E = len(surface), K * V * U
        self.points, self.rays = N, len(ray_point)
        self._F = sp.csr_matrix((vals.astype(np.float32), (rows, cols)), shape=(N, E))
        self._fitted = np.unique(cols)                            # the entries that land on a point
        fitted = self._F[:, self._fitted]
        self._products = RowBlocks(fitted), RowBlocks(fitted.T)
        self._gather = sp.csr_matrix((weights.astype(np.float32), (ray_point, np.arange(len(ray_point)))),
                                     shape=(N, len(ray_point)))
        self.origins, self.directions = origins.astype(np.float32), directions.astype(np.float32)
        for a in (self.origins, self.directions):
            a.flags.writeable = False
        landed = np.zeros(E, bool)
        landed[self._fitted] = True
        self.landed = landed.reshape(K, V, U)
        self.landed.flags.writeable = False
        data = np.tile(LightField.zeros(array, U, V).mask().ravel(), K)
        projector = encoder.projector
        self.emission = (projector.max_radiance * projector.cross_talk_matrix).astype(np.float32)
        # each channel's light field entries: 0 up to the channel's own full drive; none off the data samples
        self._upper = (data[self._fitted, None] * np.diag(self.emission)[None, :]).astype(np.float32)
        self._lipschitz: float | None = None
        self._last: tuple[np.ndarray, np.ndarray] | None = None   # (target, light field) of the last solve
        self.history: deque[SolveRecord] = deque(maxlen=HISTORY)
        self.live = False

    @cached_property
    def drive(self) -> ProjectorDrive:
        """The model projector's :class:`~lftransfer.lightfield.devices.ProjectorDrive` (S and M): what its pixels
        emit, to judge a solve by (built on first use: the solve itself does not need it)."""
        return ProjectorDrive(self.encoder)

    @property
    def shape(self) -> tuple[int, int, int]:
        """The projector's drive image shape (H, W, 3)."""
        device = self.encoder.codec.device
        return (device.height, device.width, 3)

    @staticmethod
    def _geometry(surface, array, U, V, M, seed):
        """F's entries and the target's rays: every (point, lenslet, aperture point) whose direction is inside
        the lenslet's window, in front of the point's surface and not hidden by the measured depth."""
        P, normals, conf, depth = surface.points, surface.normals, surface.confidence, surface.depth
        a = array.half_width
        z = np.maximum(P[:, 2], 1e-6)
        rel = P[:, None, :2] - array.centres[None, :, :]                            # (N, K, 2)
        reach = a + 0.75 * array.pitch / z                                         # centre ray plus an aperture
        n_idx, k_idx = np.nonzero(np.all(np.abs(rel) <= (reach * z)[:, None, None], axis=2))
        # visibility from the lenslet's centre, by the depth measured along the entry nearest the direction
        slope = rel[n_idx, k_idx] / z[n_idx, None]
        col = np.clip(np.floor((slope[:, 0] + a) * U / (2 * a)).astype(np.int64), 0, U - 1)
        row = np.clip(np.floor((slope[:, 1] + a) * V / (2 * a)).astype(np.int64), 0, V - 1)
        seen = depth[k_idx, row, col]
        keep = ~(np.isfinite(seen) & (P[n_idx, 2] > seen + VISIBILITY_TOLERANCE_M))
        n_idx, k_idx = n_idx[keep], k_idx[keep]
        offsets = array.sample_aperture(M, seed=seed)                               # (M, 2)
        n_r, k_r = np.repeat(n_idx, M), np.repeat(k_idx, M)
        p = np.zeros((len(n_r), 3))
        p[:, :2] = array.centres[k_r] + np.tile(offsets, (len(n_idx), 1))
        w = P[n_r] - p
        r2 = np.einsum("ij,ij->i", w, w)
        d = w / np.sqrt(r2)[:, None]                                                # lenslet -> point
        u, v = d[:, 0] / d[:, 2], d[:, 1] / d[:, 2]
        cos_n = -np.einsum("ij,ij->i", normals[n_r], d)
        ok = (np.abs(u) <= a) & (np.abs(v) <= a) & (cos_n > 0)
        n_r, k_r, p, d, u, v, r2, cos_n = n_r[ok], k_r[ok], p[ok], d[ok], u[ok], v[ok], r2[ok], cos_n[ok]
        g = array.aperture_area / M * d[:, 2] * cos_n / r2 * conf[n_r]              # W m^-2 per W m^-2 sr^-1
        # the bilinear read of the lenslet's table at (u, v), as the projector's lenslets read theirs
        fx = np.clip((u + a) * U / (2 * a) - 0.5, 0.0, U - 1.0)
        fy = np.clip((v + a) * V / (2 * a) - 0.5, 0.0, V - 1.0)
        x0 = np.minimum(np.floor(fx).astype(np.int64), max(U - 2, 0))
        y0 = np.minimum(np.floor(fy).astype(np.int64), max(V - 2, 0))
        tx, ty = fx - x0, fy - y0
        base = (k_r * V + y0) * U + x0
        dx, dy = (1 if U > 1 else 0), (U if V > 1 else 0)
        rows = np.tile(n_r, 4)
        cols = np.concatenate([base, base + dx, base + dy, base + dy + dx])
        vals = np.concatenate([g * (1 - tx) * (1 - ty), g * tx * (1 - ty), g * (1 - tx) * ty, g * tx * ty])
        return rows, cols, vals, n_r, p, -d, g

    # ------------------------------------------------------------------ the maps
    def target(self, radiance: np.ndarray) -> np.ndarray:
        """(N, 3) float32 irradiance at the points from the radiance (R, 3) the synthetic objects send along
        :attr:`origins` / :attr:`directions`."""
        radiance = np.asarray(radiance, np.float32)
        if radiance.shape != (self.rays, 3):
            raise ValueError(f"radiance has shape {radiance.shape}, expected {(self.rays, 3)}")
        return np.asarray(self._gather @ radiance, np.float32)

    def irradiance(self, lf: LightField | np.ndarray) -> np.ndarray:
        """(N, 3) float32 irradiance F X at the points from a light field the projector emits (above black)."""
        x = lf.data if isinstance(lf, LightField) else lf
        return np.asarray(self._F @ np.asarray(x, np.float32).reshape(-1, 3), np.float32)

    def emitted(self, drive: np.ndarray) -> np.ndarray:
        """(K, V, U, 3) float32 S (d M^T): the light field the model's projector emits above black for a drive
        image (H, W, 3) in [0, 1]."""
        return self.drive(drive)

    def encoded_drive(self, lf: LightField) -> np.ndarray:
        """(H, W, 3) float32 in [0, 1]: the drive the encoder sends for a light field (above black): its bilinear
        resampling onto the pixels, the colour cross-talk undone, clipped (before the response and quantisation)."""
        image = self.encoder.codec.lightfield_to_image(lf)
        inverse = np.linalg.inv(self.emission.astype(np.float64)).astype(np.float32)
        return np.clip(image.reshape(-1, 3) @ inverse.T, 0.0, 1.0).reshape(self.shape).astype(np.float32)

    # ------------------------------------------------------------------ the solve
    def solve(self, lf: TargetedLightField, *, iterations: int | None = None) -> LightField:
        """The light field (above black) whose light best gives the measured surface ``lf.target``: the entries
        whose light lands on a measured point are fitted, each channel between 0 and its full drive; the others
        keep ``lf``'s values (module docstring).

        Args:
            lf: the synthetic light field with its target.
            iterations: the steps (default :data:`ITERATIONS`, or :data:`WARM_ITERATIONS` from the last solution
                when the target changed little).
        """
        target = np.asarray(lf.target, np.float32)
        if target.shape != (self.points, 3):
            raise ValueError(f"target has shape {target.shape}, expected {(self.points, 3)}")
        box = np.asarray(lf.data, np.float32).reshape(-1, 3)
        last = self._last
        warm = last is not None and (self.live or np.linalg.norm(target - last[0])
                                     < WARM_CHANGE * np.linalg.norm(target))
        start = last[1] if warm else box[self._fitted]
        steps = iterations if iterations is not None else (WARM_ITERATIONS if warm else ITERATIONS)
        t0 = time.perf_counter()
        forward, backward = self._products
        fit = box_least_squares(lambda x: np.asarray(forward @ x, np.float32),
                                lambda r: np.asarray(backward @ r, np.float32), target, start, self._upper,
                                iterations=steps, lipschitz=self._lipschitz, monotone=False, tolerance=TOLERANCE)
        self._lipschitz = fit.lipschitz
        self._last = (target, fit.x)
        self._last_box = box[self._fitted]
        self.history.append(SolveRecord(bool(warm), len(fit.losses), time.perf_counter() - t0, fit.losses[0],
                                        fit.losses[-1]))
        out = box.copy()
        out[self._fitted] = fit.x
        return LightField(out.reshape(lf.data.shape), lf.array)

    def last_misfit(self) -> dict[str, float] | None:
        """How far the last solve is from converged: the relative misfit |c (F X - T)| / |c T| of its solution and
        of the same target solved from the box light field for :data:`ITERATIONS` steps (nothing kept of that
        solve). A live frame takes :data:`WARM_ITERATIONS` steps from the last frame's solution; this says what
        that costs. None before any solve."""
        if self._last is None:
            return None
        target, x = self._last
        forward, backward = self._products
        norm = max(float(np.linalg.norm(target)), 1e-30)
        fit = box_least_squares(lambda v: np.asarray(forward @ v, np.float32),
                                lambda r: np.asarray(backward @ r, np.float32), target, self._last_box, self._upper,
                                iterations=ITERATIONS, lipschitz=self._lipschitz, monotone=False, tolerance=TOLERANCE)
        return {"misfit": float(np.linalg.norm(forward @ x - target)) / norm,
                "converged_misfit": float(np.linalg.norm(forward @ fit.x - target)) / norm,
                "box_misfit": float(np.linalg.norm(forward @ self._last_box - target)) / norm}


class SolvingEncoder:
    """The synthetic side's encoder: a :class:`TargetedLightField` is solved against the measured surface
    (:meth:`SurfaceSolve.solve`, then the drive quantised to the projector's codes); any other light field (a
    calibration pattern, the depth's white frame, the box or prefiltered projections) is encoded as the wrapped
    encoder encodes it, bit for bit.

    Args:
        encoder: the rig model's :class:`~lftransfer.lightfield.LightFieldEncoder`.

    Attributes:
        solve: the :class:`SurfaceSolve` of the measured surface, or None (set by the synthetic side once the depth
            is measured).
    """

    def __init__(self, encoder) -> None:
        self.encoder = encoder
        self.solve: SurfaceSolve | None = None

    def __getattr__(self, name: str):
        return getattr(self.encoder, name)

    def __call__(self, lf: LightField) -> np.ndarray:
        if isinstance(lf, TargetedLightField) and self.solve is not None and lf.target is not None \
                and len(lf.target) == self.solve.points and np.any(lf.target):
            return self.encoder(self.solve.solve(lf))
        return self.encoder(lf)
