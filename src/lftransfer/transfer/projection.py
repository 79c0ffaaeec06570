"""The projector's side of the reconstruction: a prefilter of the projected light field from a measured depth.

A projector lenslet sends one radiance per direction over its whole aperture. The box prefilter (each entry the
mean of the synthetic light over the aperture, what
:meth:`~lftransfer.render.renderer.HalfSpaceRenderer.render_lightfield` renders) therefore gives a real point
every direction's light blurred over a lenslet. But a real point receives from each lenslet a range of directions
that shifts as the point moves, so a light field whose entries vary with direction can put more of the synthetic
light where it belongs. Knowing where each projected ray lands:

1. the depth of the real scene is measured through the rig (:func:`measure_depth`: the projector shows white, the
   LF camera captures, the direct frame is subtracted, and :func:`~lftransfer.lightfield.depth.plane_sweep` finds
   the depth where neighbouring lenslets agree);
2. every ray of the light field render (``spp`` stratified aperture points per entry: the scene's
   ``[render] lf_spp``) lands on the plane of its entry's depth; the landing points are binned (:data:`BIN_M`).
   The rays are the fit's model of where each entry's light lands: four sample an entry's footprint (a lenslet
   wide) too coarsely for an edge sharper than a lenslet, 16 do better (Fig. 5's penumbra:
   benchmarks/reconstruction/projector_prefilter.py --fig5);
3. the projected entries P are chosen so that every bin receives the light the synthetic scene sends along the
   rays that land in it (:class:`DepthPrefilter`)::

       min_P  sum_bins (sum_{rays r in bin} w_r (P[entry(r)] - Ls(r)))^2  +  (DAMP s)^2 |P - P_box|^2,

   ``w_r`` a ray's projected solid angle over ``spp``, ``s`` the RMS column norm, subject to P >= 0 (a projector
   cannot send negative light): the unconstrained solution (a sparse factorisation of the bins' normal matrix,
   made once per depth) clipped at zero starts an accelerated projected gradient (a live loop's next frame, whose
   light changed little, starts from the last solution and takes fewer steps);
4. on each lenslet the entries whose rays land keep the box light field's power over them: the prefilter moves
   light between the directions that reach the real objects, it does not add any (where the depth is wrong, a
   fit that may add light sends too much to the real objects: 13 to 21 % on the study scenes).

Entries whose rays land nowhere (no depth: dark, or past the sweep's range) keep their box value. The measured
effect, per scene: benchmarks/reconstruction/projector_prefilter.py (why: docs/architecture.md, "The projector's
side").
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from lftransfer.lightfield import LightField
from lftransfer.lightfield.depth import SWEEP_DEPTHS, plane_sweep
from lftransfer.render.base import data_entry_rays, sample_mean

#: Side of the landing bins, metres.
BIN_M = 0.004
#: Pull towards the box light field, relative to the RMS column norm of the bins' matrix.
DAMP = 0.3
#: Steps of the non-negative fit (on the study scenes at the paper's resolution 30 give what 150 give).
ITERATIONS = 30
#: Steps from the previous solution when the light to fit changed little since it (a live loop's next frame).
WARM_ITERATIONS = 10
#: "Changed little": the targets' relative change below this.
WARM_CHANGE = 0.2
#: Fraction of the projector's full radiance shown by :func:`measure_depth`'s white light field.
WHITE_FILL = 0.5


@dataclass(frozen=True)
class MeasuredDepth:
    """The real scene's depth as :func:`measure_depth` measures it.

    Attributes:
        depth: (K, V, U) float64 depth along each sample's centre ray, metres along the array's normal; NaN where
            none was found (:func:`~lftransfer.lightfield.depth.plane_sweep`).
        response: the light field it was swept from: the real scene lit by the projector alone, white
            (:data:`WHITE_FILL` of its full radiance) on every entry, (K, V, U, 3) W m^-2 sr^-1; it also tells which
            rays meet a real object at all (:mod:`lftransfer.real_depth.outline`).
    """

    depth: np.ndarray
    response: LightField


def measure_depth(rig, decoder, encoder, max_radiance: float, U: int, V: int, direct: LightField, *,
                  depths: np.ndarray = SWEEP_DEPTHS) -> MeasuredDepth:
    """The real scene's depth, measured through the rig: one extra frame with the projector white, less ``direct``.

    Args:
        rig: the rig (``project``, ``capture_lf``, ``info.black()``), set up in the real scene.
        decoder: raw LF camera image -> LightField; encoder: LightField -> projector image (the rig model's).
        max_radiance: the projector's full radiance (rig model), W m^-2 sr^-1.
        U, V: the light field grid.
        direct: the decoded capture with the projector black (the real point light alone).
        depths: candidate depths of the sweep, metres.

    Returns:
        :class:`MeasuredDepth`. The projector is left black.
    """
    white = LightField.zeros(direct.array, U, V)
    white.data[:] = WHITE_FILL * max_radiance * white.mask()[None, :, :, None]
    rig.project(encoder(white))
    lit = decoder(rig.capture_lf().codes) - direct
    rig.project(rig.info.black())
    return MeasuredDepth(plane_sweep(lit, depths), lit)


@dataclass(eq=False)
class DepthPrefilter:
    """The projected light field's prefilter for one depth map and one set of light field rays (module docstring).

    Args:
        depth: (K, V, U) depth of each entry's centre ray, metres (NaN: unknown).
        U, V: the grid; array: the lens array (with ``depth``'s K lenslets).
        spp: rays per entry.
        seed: the rays' seed (their aperture points are fixed, so the factorisation is made once).
        bin_m, damp: landing bins' side (m) and the pull towards the box light field.

    Attributes:
        origins, directions: (E * spp, 3) float32 read-only rays of the light field render, of the E entries with
            data (:meth:`LightField.mask`; lenslet, direction, sample order; directions look into the synthetic
            half-space, as :func:`~lftransfer.render.renderer.lightfield_rays` makes them).
        landed: (K, V, U) bool, entries with at least one ray that lands on the measured surface.
        bins: number of landing bins.

    Example:
        >>> pf = DepthPrefilter(depth, array, U, V, spp=4)                            # doctest: +SKIP
        >>> radiance = renderer.render_samples(pf.origins, pf.directions, lights, 1).radiance  # doctest: +SKIP
        >>> ls = pf.apply(radiance)                                                           # doctest: +SKIP
    """

    depth: np.ndarray
    array: object
    U: int
    V: int
    spp: int = 4
    seed: int = 0
    bin_m: float = BIN_M
    damp: float = DAMP
    origins: np.ndarray = field(init=False, repr=False)
    directions: np.ndarray = field(init=False, repr=False)
    landed: np.ndarray = field(init=False, repr=False)
    bins: int = field(init=False)

    def __post_init__(self) -> None:
        K, V, U, S = self.array.K, self.V, self.U, self.spp
        if self.depth.shape != (K, V, U):
            raise ValueError(f"depth has shape {self.depth.shape}, the light field needs {(K, V, U)}")
        self._zero = LightField.zeros(self.array, U, V)
        self.origins, self.directions, entries = data_entry_rays(self.array, U, V, area=True, spp=S, seed=self.seed)
        for a in (self.origins, self.directions):
            a.flags.writeable = False
        self._channels = np.repeat(entries, 3)                              # their values in the flat table
        cast = np.flatnonzero(entries)                                      # cast[r // S]: the entry of ray r
        # every ray of an entry with a depth meets the plane at that depth, parallel to the array
        rays = np.flatnonzero(np.repeat(np.isfinite(self.depth.reshape(-1))[cast], S))   # among the rays cast
        entry = cast[rays // S]
        towards = -self.directions[rays].astype(np.float64)                 # into the real half-space, z > 0
        points = self.origins[rays] + self.depth.reshape(-1)[entry][:, None] * towards / towards[:, 2:3]
        weights = self._zero.solid_angle_weights()                          # (V, U)
        w = weights.reshape(-1)[entry % (V * U)] / S
        cells = np.floor(points / self.bin_m).astype(np.int64)
        bins = np.unique(cells, axis=0, return_inverse=True)[1].ravel() if len(rays) else np.zeros(0, np.int64)
        self.bins = int(bins.max() + 1) if len(bins) else 0
        self._gather = sp.csr_matrix((w.astype(np.float32), (bins, rays)),          # target = G @ Ls(r): float32,
                                     shape=(self.bins, len(self.origins)))          # as the rays' radiance is
        self._cols = np.unique(entry)                                       # the landing entries, sorted
        self.landed = np.zeros(K * V * U, bool)
        self.landed[self._cols] = True
        self.landed = self.landed.reshape(K, V, U)
        self._col_lenslet = self._cols // (V * U)                           # each landing entry's lenslet
        self._col_weight = weights.reshape(-1)[self._cols % (V * U)]        # and its solid angle weight
        self._lu, self._last = None, None
        if self.bins:
            # bins <- landing entries (the other entries' columns would be empty)
            self._ml = sp.csr_matrix((w, (bins, np.searchsorted(self._cols, entry))),
                                     shape=(self.bins, len(self._cols)))
            self._mlt = self._ml.T.tocsr()
            norms = np.sqrt(np.asarray(self._ml.multiply(self._ml).sum(0)).ravel())
            self._lam2 = (self.damp * np.sqrt(np.mean(norms ** 2))) ** 2
            self._lu = splu((self._ml @ self._mlt + self._lam2 * sp.identity(self.bins)).tocsc())
            v = np.random.default_rng(0).random(len(self._cols))                # power iteration: |M|^2
            for _ in range(30):
                v = self._mlt @ (self._ml @ v)
                top = float(np.linalg.norm(v))
                v /= top
            self._lipschitz = 1.05 * top + self._lam2

    def box(self, radiance: np.ndarray) -> LightField:
        """The box light field of the rays' radiance: each entry the mean of its ``spp`` rays (K, V, U, 3)."""
        lf = self._zero.copy()
        lf.data.reshape(-1)[self._channels] = sample_mean(radiance, self.spp).ravel()
        return lf

    def apply(self, radiance: np.ndarray) -> LightField:
        """The prefiltered light field to project.

        Args:
            radiance: (E * spp, 3) radiance the synthetic scene sends along each of :attr:`origins` /
                :attr:`directions`, W m^-2 sr^-1.

        Returns:
            LightField (K, V, U, 3) float32: the box light field where no ray lands, the fit elsewhere.
        """
        radiance = np.asarray(radiance, np.float32)
        if radiance.shape != (len(self.origins), 3):
            raise ValueError(f"radiance has shape {radiance.shape}, expected {(len(self.origins), 3)}")
        box = self.box(radiance)
        if self._lu is None:
            return box
        target = (self._gather @ radiance).astype(np.float64)
        fitted = box.data.reshape(-1, 3)[self._cols].astype(np.float64)       # the box entries being fitted
        last = self._last
        if last is not None and np.linalg.norm(target - last[0]) < WARM_CHANGE * np.linalg.norm(target):
            start, steps = last[1], WARM_ITERATIONS
        else:
            start, steps = fitted + self._mlt @ self._lu.solve(target - self._ml @ fitted), ITERATIONS
        fit = self._nonnegative(target, fitted, start, steps)
        self._last = (target, fit)
        # each lenslet's landing entries keep the box power over them (only they change: the rest is the box)
        lenslet, w, K = self._col_lenslet, self._col_weight, self.array.K
        kept, now = (np.stack([np.bincount(lenslet, weights=p[:, c] * w, minlength=K) for c in range(3)], -1)
                     for p in (fitted, fit))
        scale = np.where(now > 0, kept / np.maximum(now, 1e-300), 1.0)
        box.data.reshape(-1, 3)[self._cols] = (fit * scale[lenslet]).astype(np.float32)
        return box

    def _nonnegative(self, target: np.ndarray, p0: np.ndarray, start: np.ndarray, steps: int) -> np.ndarray:
        """The damped fit restricted to P >= 0 over the landing entries: accelerated projected gradient (FISTA)
        from ``start`` clipped at zero: the unconstrained solution (:data:`ITERATIONS` steps; clipping alone leaves
        most of the fit's gain on the table: a round trip through a plane measured 0.201 clipped, 0.182
        constrained, against the box light field's 0.214; tests/transfer/test_projection.py) or, when the light
        to fit changed little since the last call, the last solution (:data:`WARM_ITERATIONS` steps).

        Args:
            target: (bins, 3) the light each bin should receive; p0: (n, 3) the box entries being fitted.
            start: (n, 3) where the steps start; steps: how many.

        Returns:
            (n, 3) float64 entries >= 0.
        """
        x = np.maximum(start, 0.0)
        y, step, momentum = x.copy(), 1.0 / self._lipschitz, 1.0
        lam2_p0 = self._lam2 * p0
        new, diff = np.empty_like(x), np.empty_like(x)
        for _ in range(steps):
            residual = self._ml @ y
            residual -= target
            gradient = self._mlt @ residual                 # + lam2 (y - p0), in place below
            gradient += self._lam2 * y
            gradient -= lam2_p0
            np.multiply(gradient, -step, out=new)
            new += y
            np.maximum(new, 0.0, out=new)
            following = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * momentum**2))
            np.subtract(new, x, out=diff)
            diff *= (momentum - 1.0) / following
            np.add(new, diff, out=y)
            x, new = new, x
            momentum = following
        return x


__all__ = ["BIN_M", "DAMP", "DepthPrefilter", "ITERATIONS", "WARM_CHANGE", "WARM_ITERATIONS",
           "WHITE_FILL", "MeasuredDepth", "measure_depth"]
