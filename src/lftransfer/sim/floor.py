"""The fidelity floor: how close any algorithm could bring the cross-transfer term through this rig, found on the
simulated rig with the truth (docs/architecture.md, "The fidelity floor").

Real side: the best projector image. The real objects' added light in the view camera is linear in what the
projector's lenslets emit, V(X) = A X, with X the light field emitted above the projector's black and A the
simulated rig's own view render of its projector light (the same rays, paths, aperture points and seeds as its
captures, :meth:`SimRig.capture_view`); and X is linear in the projector's linear drive d (per pixel and
channel, in [0, 1]: the response curve's decoded code): X = S (d E^T), with E the projector's emission per unit
drive (its maximum radiance times its colour cross-talk) and S the rig's own resampling of projector pixels onto
its lenslets' light field (:meth:`LensletCodec.image_to_lightfield_matrix`, the same taps and weights). The floor
is

    min over 0 <= d <= 1 of || M D ((1 - alpha) A S (d E^T) + alpha dS) - C_gt ||^2

over the pixels where only real objects are seen (M; D the metrics' box downsampling; alpha and dS the
transfer's own synthetic coverage and added synthetic light, which on those pixels are a thin edge), solved by
projected gradient descent with Nesterov momentum and a monotone safeguard (MFISTA), started from the transfer's
own projection so that it can only improve on it. The gradient is the exact transpose of each map: S^T (a sparse
matrix's transpose) and A^T (:meth:`HalfSpaceRenderer.render_view_adjoint`: the render's gathers scattered
back), not Dr.Jit's automatic differentiation: the lenslets' symbolic loop would have to be recorded iteration
by iteration for that (a copy of the image's state per lenslet and aperture point, 240 for the paper's array, at
every path vertex), while the transpose of a linear map needs none. The optimum is then quantised to projector
codes by the true encoder (the rig as built) and projected as the rig would, so the floor reported is an image
the projector can show; the optimum before quantisation is reported beside it (``relaxed``).

The truth it is fitted to is the ground truth's first seed and the score is taken against its second (and the
transfer's own projection is scored the same way), so the floor cannot pass for good by fitting the reference's
noise: with more light field entries than pixels it could fit that noise exactly. A score against one noisy seed
overstates every error by that seed's noise; since the seed's noise is independent of what is scored, its
expected square, half the squared difference of the two seeds' cross terms, is taken off each squared error
(the noise-corrected error; both the floors and the transfer's error as scored here are corrected so). Fitted to a
noisy seed, the fit follows that seed's noise the longer it runs, and its held-out score rises again (on Fig. 4
at quarter resolution with a 512-sample reference: lowest after 10 to 20 steps, a third higher after 120); so it
is stopped early: the points after 5, 10, 20 and 40 steps are each quantised and scored, and the best is kept.
Choosing among four on the seed that scores them flatters the floor a little; a quiet reference leaves less
noise to follow.

Synthetic side: the synthetic objects lit by the light field the real objects really send, sampled as the LF
camera samples it (the true array, the run's angular grid, aperture-averaged, 16 rays per entry, no sensor
noise, no codec), rendered by the run's own renderer with the run's samples (so the floor keeps the renderer's
own sampling noise, as the transfer does): what one sample per lenslet and direction allows.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from lftransfer.lightfield.devices import ProjectorDrive
from lftransfer.sim.metrics import cross_term_truth, downsample, metric_factor, object_mask
from lftransfer.transfer.solver import FLOOR_ITERATIONS, BoxFit, box_least_squares

_log = logging.getLogger(__name__)

__all__ = ["BoxFit", "FidelityFloor", "ProjectorOperator", "SideFloor", "box_least_squares", "fidelity_floor",
           "nonnegative_bound", "real_floor", "score_cross", "synthetic_floor", "true_incident_lightfield"]

FLOOR_STOPS = (5, 10, 20)      # the earlier steps of FLOOR_ITERATIONS whose point is scored too (early stopping)
TRUE_LF_SPP = 16               # rays per light field entry of the synthetic side's true light field


class ProjectorOperator:
    """The simulated rig's view of its real objects as a linear map of its projector's light field.

    ``forward(X)`` is the view camera's radiance added by the projector emitting X above its black ((K, V, U, 3),
    the projector codec's grid, W m^-2 sr^-1) in the real scene, as :meth:`SimRig.capture_view` renders it (the
    same rays, paths and seeds); ``adjoint(W)`` its transpose. Every lenslet is visited, while a capture visits
    those that carry light: where some are dark, the others take their aperture points in another order (the same
    estimator with other samples), so the transfer's own projection is scored through this operator too.

    Args:
        rig: the :class:`~lftransfer.sim.rig.SimRig`, in its real-scene set-up.
    """

    def __init__(self, rig) -> None:
        from lftransfer.lightfield import LightField
        from lftransfer.render.lights import LightFieldLight

        self.rig = rig
        info = rig.info
        black = info.black()
        white = np.full_like(black, (1 << info.projector_bits) - 1)
        self.black = self._emitted_lf(black)
        self.white = self._emitted_lf(white) - self.black          # X_white: the range of each entry
        self.projector = rig._prj_encoder.projector
        self.drive = ProjectorDrive(rig._prj_encoder)                 # X = S (d E^T), the true projector's
        self.drive_shape = black.shape
        ones = LightField(np.ones_like(self.black), rig.truth.array)
        self.light = LightFieldLight(ones, side="real", model="area", aperture_samples=rig.aperture_samples,
                                     seed=rig._seed + 3)
        self.width, self.height = rig._view.resolution

    def _emitted_lf(self, codes: np.ndarray) -> np.ndarray:
        """(K, V, U, 3) what the projector's lenslets emit for projector ``codes``."""
        rig = self.rig
        return rig._prj_codec.image_to_lightfield(rig._prj_encoder.emitted(codes)).data.astype(np.float32)

    def of_codes(self, codes: np.ndarray) -> np.ndarray:
        """X of a projector image: what it emits above the black."""
        return self._emitted_lf(codes) - self.black

    def drive_of(self, codes: np.ndarray) -> np.ndarray:
        """(H, W, 3) float32 linear drive of projector ``codes`` (the true response curve), in [0, 1]."""
        prj = self.projector
        return prj.response.decode(codes.astype(np.float32) / np.float32(prj.levels)).astype(np.float32)

    def codes_of_drive(self, drive: np.ndarray) -> np.ndarray:
        """The projector image the rig as built shows for a linear drive (its true encoder's quantisation)."""
        return self.rig._prj_encoder.quantise(self.projector.emit(np.clip(drive, 0.0, 1.0)))

    def lf_of_drive(self, drive: np.ndarray) -> np.ndarray:
        """X = S (d E^T): (K, V, U, 3) light field emitted above the black for an (H, W, 3) linear drive."""
        return self.drive(drive)

    def drive_adjoint(self, grad: np.ndarray) -> np.ndarray:
        """The transpose of :meth:`lf_of_drive`: (K, V, U, 3) -> (H, W, 3)."""
        return self.drive.adjoint(grad)

    def forward(self, x: np.ndarray) -> np.ndarray:
        """(H, W, 3) view radiance added by X."""
        rig = self.rig
        self.light.set_data(x)
        return rig._real.render_view(rig._view_sensor, self.width, self.height, [self.light], spp=rig.view_spp,
                                     seed=rig._seed).rgb

    def adjoint(self, weights: np.ndarray) -> np.ndarray:
        """(K, V, U, 3) A^T ``weights`` ((H, W, 3))."""
        rig = self.rig
        self.light.zero_grad()
        rig._real.render_view_adjoint(rig._view_sensor, self.width, self.height, self.light, weights,
                                      spp=rig.view_spp, seed=rig._seed)
        return self.light.grad()


class JointProjectors:
    """Several interfaces' projectors as one linear map (docs/interfaces.md): the view camera's radiance added by
    every projector, :class:`ProjectorOperator`'s methods over them all. A drive or a set of codes is (I, H, W, 3),
    one projector's on each first index (every interface has ``[rig]``'s projector); a light field is a list of
    each projector's.

    Args:
        rigs: the :class:`~lftransfer.sim.rig.SimRig` of each interface, joined in one world.
    """

    def __init__(self, rigs) -> None:
        self.ops = [ProjectorOperator(r) for r in rigs]
        self.drive_shape = (len(self.ops), *self.ops[0].drive_shape)

    def of_codes(self, codes: np.ndarray) -> list:
        return [op.of_codes(c) for op, c in zip(self.ops, codes)]

    def drive_of(self, codes: np.ndarray) -> np.ndarray:
        return np.stack([op.drive_of(c) for op, c in zip(self.ops, codes)])

    def codes_of_drive(self, drive: np.ndarray) -> np.ndarray:
        return np.stack([op.codes_of_drive(d) for op, d in zip(self.ops, drive)])

    def lf_of_drive(self, drive: np.ndarray) -> list:
        return [op.lf_of_drive(d) for op, d in zip(self.ops, drive)]

    def drive_adjoint(self, grads: list) -> np.ndarray:
        return np.stack([op.drive_adjoint(g) for op, g in zip(self.ops, grads)])

    def forward(self, xs: list) -> np.ndarray:
        """(H, W, 3) the view radiance every projector adds (each rig renders its own in its array's frame)."""
        return sum(op.forward(x) for op, x in zip(self.ops, xs))

    def adjoint(self, weights: np.ndarray) -> list:
        return [op.adjoint(weights) for op in self.ops]


@dataclass(frozen=True)
class SideFloor:
    """One side's floor, in the cross-transfer error's units: ||e|| over that side's pixels / ||C_gt|| over all
    the objects' pixels, so that the two sides add as squares to a whole error.

    Attributes:
        floor: the best found (real side: the optimum projected through the projector's codes, or the transfer's
            own projection where that is better; synthetic side: the sampled true light field).
        transfer: the run's own result scored the same way.
        relaxed: real side: the optimum before its quantisation to codes (the box relaxation), else None.
        noise: the ground truth's second seed's own noise on these pixels, the same units (taken off the squares
            of the three above, which are scored against that seed).
        pixels: pixels of this side at the metrics' resolution.
        iterations: real side: the optimiser's steps to the point kept (early stopping, module docstring),
            else 0.
        seconds: wall time.
    """

    floor: float
    transfer: float
    relaxed: float | None
    noise: float
    pixels: int
    iterations: int = 0
    seconds: float = 0.0


@dataclass(frozen=True)
class FidelityFloor:
    """Both sides' floors and the whole (:func:`fidelity_floor`).

    Attributes:
        real, synthetic: :class:`SideFloor` of each side (None where a side has no pixels or no cross term).
        floor: sqrt(real.floor^2 + synthetic.floor^2): the smallest cross-transfer error this rig allows.
        transfer: the run's own error scored as the floors are (real side against the held-out seed).
        transfer_over_floor: transfer / floor.
        notes: what the floor assumes.
    """

    real: SideFloor | None
    synthetic: SideFloor | None
    floor: float | None
    transfer: float | None
    transfer_over_floor: float | None
    notes: list[str] = field(default_factory=list)

    @property
    def real_floor(self) -> float | None:
        """The real side's floor (None without that side)."""
        return self.real.floor if self.real is not None else None

    @property
    def synthetic_floor(self) -> float | None:
        """The synthetic side's floor (None without that side)."""
        return self.synthetic.floor if self.synthetic is not None else None

    def to_json(self) -> dict:
        from dataclasses import asdict

        return {"real": asdict(self.real) if self.real else None,
                "synthetic": asdict(self.synthetic) if self.synthetic else None,
                "floor": self.floor, "transfer": self.transfer, "transfer_over_floor": self.transfer_over_floor,
                "notes": list(self.notes)}


@dataclass
class _Metric:
    """The cross-transfer error's pixels and truth at the metrics' resolution."""

    factor: int
    pair: list            # the two seeds' cross terms, (h, w, 3) each
    covered: np.ndarray   # (h, w) bool
    synthetic: np.ndarray  # (h, w) bool, a synthetic object is seen
    norm: float           # ||C_gt|| (mean of the pair) over the covered pixels

    @property
    def real_pixels(self) -> np.ndarray:
        """(h, w) bool: the real side's pixels (covered, no synthetic object seen)."""
        return self.covered & ~self.synthetic

    @property
    def synthetic_pixels(self) -> np.ndarray:
        """(h, w) bool: the synthetic side's pixels (a synthetic object seen)."""
        return self.covered & self.synthetic

    @classmethod
    def of(cls, gt, width: int, target_width: int) -> "_Metric":
        f = metric_factor(width, target_width)
        pair = cross_term_truth(gt, f)
        covered = object_mask(gt, f)
        c_gt = 0.5 * (pair[0] + pair[1])
        return cls(f, pair, covered, downsample(gt.synthetic_seen, f) > 0.5,
                   float(np.sqrt(np.sum(c_gt[covered] ** 2))))

    def score(self, c: np.ndarray, where: np.ndarray) -> float:
        """The noise-corrected error of a cross term ``c`` ((h, w, 3)) over ``where`` against the second seed, in
        the error's units: sqrt(max(0, ||c - C_2||^2 - ||C_1 - C_2||^2 / 2)) / ||C_gt|| (module docstring)."""
        e2 = float(np.sum((c - self.pair[1])[where] ** 2))
        n2 = 0.5 * float(np.sum((self.pair[0] - self.pair[1])[where] ** 2))
        return float(np.sqrt(max(0.0, e2 - n2))) / self.norm

    def noise(self, where: np.ndarray) -> float:
        """One seed's noise on the cross term over ``where``, in the error's units."""
        return float(np.sqrt(0.5 * np.sum((self.pair[0] - self.pair[1])[where] ** 2))) / self.norm

    def up(self, small: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
        """D^T: (h, w, 3) at the metrics' resolution -> (H, W, 3), each value spread over its block / f^2."""
        f = self.factor
        big = np.zeros((*shape, 3), np.float32)
        h, w = small.shape[:2]
        big[:h * f, :w * f] = np.repeat(np.repeat(small, f, axis=0), f, axis=1) / np.float32(f * f)
        return big


def nonnegative_bound(apply: Callable[[np.ndarray], np.ndarray], target: np.ndarray, upper: np.ndarray) -> float:
    """A lower bound of min ||A x - b||^2 over 0 <= x <= upper for a non-negative A (light adds, never takes away):
    A x >= 0 everywhere and is 0 wherever A upper is (no light of the projector reaches there), so no x does
    better than b^2 summed over those values and over the values where b < 0."""
    reach = apply(upper)
    b = np.asarray(target, np.float64)
    return float(np.sum(np.where((reach <= 0) | (b < 0), b * b, 0.0)))


def real_floor(rig, result, gt, *, target_width: int = 256, iterations: int = FLOOR_ITERATIONS,
               progress: Callable[[str], None] | None = None) -> SideFloor | None:
    """The real side's floor (module docstring): the best projector image for the real objects' cross term.

    Args:
        rig: the :class:`~lftransfer.sim.rig.SimRig` the run transferred through (its real scene in place); with
            several interfaces, the list of their rigs (every projector's drive is searched at once,
            :class:`JointProjectors`).
        result: the run's :class:`~lftransfer.transfer.TransferResult`.
        gt: the ground truth at the view's resolution.
        target_width: the metrics' width.
        iterations: MFISTA steps.
        progress: called with a message every 10 steps.

    Returns:
        :class:`SideFloor`, or None where no pixel shows only real objects or the truth has no cross term there.
    """
    t0 = time.perf_counter()
    h, w = result.real_view.shape[:2]
    m = _Metric.of(gt, w, target_width)
    where = m.real_pixels
    if not where.any() or not m.norm > 0:
        return None
    alpha = result.synthetic_view.alpha.astype(np.float32)[..., None]
    d_syn = alpha * (result.synthetic_view.rgb - result.bounces[0].synthetic_view.rgb)
    base = downsample(d_syn, m.factor)                        # the synthetic part on these pixels, held
    target = np.where(where[..., None], m.pair[0] - base, 0.0)    # fitted to the first seed (module docstring)
    several = isinstance(rig, (list, tuple))
    op = JointProjectors(rig) if several else ProjectorOperator(rig)
    projected = np.stack(result.projected_images) if several else result.projected_image
    weight = 1.0 - alpha                                      # what of the real view the composite shows

    def apply(x: np.ndarray) -> np.ndarray:
        return np.where(where[..., None], downsample(weight * op.forward(x), m.factor), 0.0)

    def transpose(r: np.ndarray) -> np.ndarray:
        return op.adjoint(weight * m.up(r.astype(np.float32), (h, w)))

    def error(x: np.ndarray) -> float:                        # scored against the second seed, over ``where``
        return m.score(apply(x) + base, where)

    ones = np.ones(op.drive_shape, np.float32)
    stops = tuple(k for k in FLOOR_STOPS if k < iterations) + (iterations,)
    fit = box_least_squares(lambda d: apply(op.lf_of_drive(d)), lambda r: op.drive_adjoint(transpose(r)), target,
                            op.drive_of(projected), ones, iterations=iterations, keep=stops,
                            progress=(lambda msg: progress(f"real floor: {msg}")) if progress else None)
    # early stopping: run long, the fit follows the first seed's noise, and the held-out score rises again
    scored = {k: error(op.of_codes(op.codes_of_drive(x))) for k, x in fit.snapshots.items()}
    steps = min(scored, key=scored.get)
    relaxed = error(op.lf_of_drive(fit.snapshots[steps]))
    transfer = error(op.of_codes(projected))
    return SideFloor(floor=min(scored[steps], transfer), transfer=transfer, relaxed=relaxed, noise=m.noise(where),
                     pixels=int(where.sum()), iterations=steps, seconds=time.perf_counter() - t0)


def true_incident_lightfield(rig, world, angular_samples: int, *, spp: int = TRUE_LF_SPP, time_s: float = 0.0,
                             seed: int = 0):
    """The light field the real objects really send to the array, sampled as the LF camera samples it: the union
    of the real and synthetic objects under the true lights (every interreflection between them), rendered at the
    true array's lenslets on the run's angular grid, aperture-averaged over ``spp`` rays per entry, without sensor
    noise or codec. (K, V, U, 3) :class:`~lftransfer.lightfield.LightField` on the true array, radiance travelling
    towards the array (what a decoded capture holds)."""
    from lftransfer.render.lights import EmitterLight, PointLight
    from lftransfer.render.renderer import HalfSpaceRenderer
    from lftransfer.scenes.frame import scene_in_frame

    truth = rig.truth
    union = scene_in_frame(world.at(time_s), truth.world_to_array())
    renderer = HalfSpaceRenderer([*union.real, *union.synthetic], max_depth=union.render.max_depth)
    lights = [PointLight(np.asarray(lt.position, float), np.asarray(lt.intensity, float)) for lt in union.lights]
    if union.emitters:
        lights.append(EmitterLight(seed=seed))
    return renderer.render_lightfield(truth.array, lights, angular_samples, angular_samples, side="real",
                                      model="area", spp=spp, seed=seed)


def synthetic_floor(rig, world, result, gt, settings, *, target_width: int = 256, spp: int = TRUE_LF_SPP,
                    time_s: float = 0.0) -> SideFloor | None:
    """The synthetic side's floor (module docstring): the synthetic objects lit by the true light field sampled as
    the LF camera samples it, rendered by the run's renderer with its settings on the true rig model.

    Args:
        rig: the :class:`~lftransfer.sim.rig.SimRig` (its truth); with several interfaces, the list of their rigs
            (each one's true light field lights the synthetic objects, as the run's sides are lit).
        world: the hidden world (``Oracle.world``: real and synthetic objects, the true lights).
        result: the run's :class:`~lftransfer.transfer.TransferResult`.
        gt: the ground truth at the view's resolution.
        settings: the run's ``TransferSettings``.
        target_width: the metrics' width.
        spp: rays per light field entry of the true light field.
        time_s: the moment of an animated scene.

    Returns:
        :class:`SideFloor` scored against the ground truth's second seed, or None where no pixel shows a synthetic
        object or the truth has no cross term.
    """
    from lftransfer.transfer.synthetic_side import SyntheticSide

    t0 = time.perf_counter()
    h, w = result.real_view.shape[:2]
    m = _Metric.of(gt, w, target_width)
    where = m.synthetic_pixels
    if not where.any() or not m.norm > 0:
        return None
    rigs = list(rig) if isinstance(rig, (list, tuple)) else [rig]
    sides = SyntheticSide.through([r.truth for r in rigs], world.synthetic_part(), settings, time_s=time_s)
    incident = [side.incident_light(true_incident_lightfield(r, world, settings.angular_samples, spp=spp,
                                                             time_s=time_s, seed=settings.seed),
                                    settings.seed + 1 + (7 * i if i else 0))
                for i, (r, side) in enumerate(zip(rigs, sides))]
    side = sides[0]
    lit = side.renderer.render_view(side.sensor, side.width, side.height, incident, spp=settings.view_spp,
                                    seed=settings.seed + 1000)
    alpha = result.synthetic_view.alpha.astype(np.float32)[..., None]
    d_real = (1.0 - alpha) * (result.real_view - result.real_view_direct)     # the real part there, held
    d_transfer = alpha * (result.synthetic_view.rgb - result.bounces[0].synthetic_view.rgb)

    def error(d_syn: np.ndarray) -> float:
        return m.score(downsample(d_syn + d_real, m.factor), where)

    return SideFloor(floor=error(alpha * lit.rgb), transfer=error(d_transfer), relaxed=None, noise=m.noise(where),
                     pixels=int(where.sum()), seconds=time.perf_counter() - t0)


def score_cross(gt, cross: np.ndarray, *, target_width: int = 256) -> tuple[float | None, float | None]:
    """A cross term as the view shows it, scored as the floors are: (real side, synthetic side), each None where
    that side has no pixels or the truth no cross term.

    Args:
        gt: the ground truth.
        cross: (H, W, 3) what the exchange adds to the composite (the composite minus the composite without any
            exchange, the projector black), W m^-2 sr^-1.
        target_width: the metrics' width.
    """
    m = _Metric.of(gt, cross.shape[1], target_width)
    if not m.norm > 0:
        return None, None
    c = downsample(cross, m.factor)
    real, syn = m.real_pixels, m.synthetic_pixels
    return (m.score(c, real) if real.any() else None), (m.score(c, syn) if syn.any() else None)


def fidelity_floor(rig, world, result, gt, settings, *, target_width: int = 256,
                   iterations: int = FLOOR_ITERATIONS, time_s: float = 0.0, cross: np.ndarray | None = None,
                   progress: Callable[[str], None] | None = None) -> FidelityFloor:
    """Both sides' floors of a run on the simulated rig and its error scored the same way (module docstring).

    Args:
        rig: the :class:`~lftransfer.sim.rig.SimRig` the run transferred through, its real scene at ``time_s``.
        world: the hidden world (``Oracle.world``).
        result: the run's :class:`~lftransfer.transfer.TransferResult` (the real side's search starts from its
            projection; the other side's light is held from it).
        gt: the ground truth.
        settings: the run's ``TransferSettings``.
        target_width, iterations, time_s: as in :func:`real_floor` and :func:`synthetic_floor`.
        cross: (H, W, 3) the cross term to score as the transfer's (:func:`score_cross`), where it is not
            ``result``'s: a live sequence's frame, whose light came from earlier captures, against a converged
            ``result`` at the same moment. The real side's floor is then also no worse than that frame.
        progress: called once per side (the real side's steps go to the log).

    Returns:
        :class:`FidelityFloor`.
    """
    say = progress or (lambda _msg: None)
    say("fidelity floor: the synthetic side (the true light field, sampled as the LF camera samples it)")
    syn = synthetic_floor(rig, world, result, gt, settings, target_width=target_width, time_s=time_s)
    say("fidelity floor: the real side (the best projector image)")
    real = real_floor(rig, result, gt, target_width=target_width, iterations=iterations, progress=_log.info)
    if cross is not None:
        real_t, syn_t = score_cross(gt, cross, target_width=target_width)
        if real is not None and real_t is not None:
            real = replace(real, transfer=real_t, floor=min(real.floor, real_t))
        if syn is not None and syn_t is not None:
            syn = replace(syn, transfer=syn_t)
    sides = [s for s in (real, syn) if s is not None]
    floor = float(np.sqrt(sum(s.floor ** 2 for s in sides))) if sides else None
    transfer = float(np.sqrt(sum(s.transfer ** 2 for s in sides))) if sides else None
    notes = ["both sides scored against the ground truth's second seed, its noise taken off the squared errors; the "
             "real side's floor was fitted to its first seed",
             "the real side's floor is the better of the best projector image found (over the projector's pixels, "
             "quantised to its codes) and the transfer's own projection"]
    if cross is not None:
        notes.append("the transfer scored is the frame as the view showed it; the real side's search started from a "
                     "converged transfer at the same moment, and its floor is no worse than the frame")
    return FidelityFloor(real=real, synthetic=syn, floor=floor, transfer=transfer,
                         transfer_over_floor=transfer / floor if floor else None, notes=notes)
