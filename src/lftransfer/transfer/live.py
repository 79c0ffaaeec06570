"""The live loop of light field transfer (docs/architecture.md, "The bounce loop" and "The live loop"): captures
and renders, either one of each per frame (``loop="sync"``) or each at its own rate (``loop="decoupled"``).

Frame t, with the projector showing the synthetic light field of frame t - 1 (black at the first frame):

1. pose the synthetic objects at time t (and ask the rig for the real scene at t: the simulated rig moves its
   real objects, a physical one moves by itself);
2. project encode(Ls_{t-1}); capture the LF camera and decode it: R_t, the real scene lit by the real point light
   *and* by Ls_{t-1};
3. capture the view camera (the real view under the same projection);
4. render the synthetic scene lit by its own light (the virtual point light, emitting objects) and by R_t: its
   outgoing light field Ls_t (shown in frame t + 1; prefiltered from the real scene's depth where the settings ask
   for it, the depth measured once before the first frame: :mod:`lftransfer.transfer.projection`) and its view S_t;
5. composite S_t with the real view (over it, or by depth: ``settings.composite``).

Each frame carries one more exchange than the one before, so for a still scene the frames converge to the
all-bounce fixed point of the bounce loop (:mod:`lftransfer.transfer.bounce`); when something moves the light
follows within a few frames. :meth:`LiveTransfer.step` is the one step function that ``lft render --mode live``,
``lft live`` and ``lft bench`` call.

With several light field interfaces (``rigs`` and ``models``, docs/interfaces.md) each step does the same through
all of them at once: every projector shows its array's Ls_{t-1}, every LF camera is captured and decoded, and the
synthetic side, lit by every R_t, renders each array's Ls_t (:func:`~lftransfer.transfer.synthetic_side.render_sides`).

Synchronous (``"sync"``): steps 2 and 3 run inside the step (:func:`~lftransfer.transfer.capture.capture_once`),
so a frame takes a capture plus a render, and a frame is always lit by the previous frame's light field. Decoupled
(``"decoupled"``): a :class:`~lftransfer.transfer.capture.CaptureWorker` captures on its own thread at the devices'
rate, each capture under the newest light field the render loop handed it; each step renders with the newest
capture there is (steps 1, 4 and 5), so a frame takes a render only, and an edit of the synthetic scene shows in
the next frame whatever the capture rate. Its light reflects the edit once a capture under a light field rendered
after it is decoded (the frame's ``light_version``); each frame says how old its capture was.
"""

from __future__ import annotations

import time
from collections import deque
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass, field
from typing import Iterator, Sequence

import numpy as np

from lftransfer import choices
from lftransfer.backend import bound_blas
from lftransfer.lightfield import LightField
from lftransfer.real_depth import ViewDepth
from lftransfer.real_depth.outline import lightfield_view_depths, on_real_side, photograph_clean_plate
from lftransfer.render.base import ViewImage
from lftransfer.rig.base import Rig
from lftransfer.rig.model import RigModel
from lftransfer.rig.requests import RealScene
from lftransfer.scenes import SyntheticScene
from lftransfer.transfer.bounce import TransferSettings, composite_view
from lftransfer.transfer.capture import Capture, CaptureWorker, Projection, capture_once
from lftransfer.transfer.projection import measure_depth
from lftransfer.transfer.share import TurnTaking
from lftransfer.transfer.synthetic_side import SyntheticSide, render_sides
from lftransfer.transfer.timer import StageTimer

__all__ = ["CAPTURE_STAGES", "FrameTimes", "InterfaceLight", "LiveFrame", "LiveTransfer", "LIVE_STAGES",
           "RENDER_STAGES"]

CAPTURE_STAGES = ("encode", "capture", "decode", "capture_view")
RENDER_STAGES = ("pose", "measure_depth", "wait_capture", "incident_light", "render_lightfield", "prefilter",
                 "render_view", "composite")
LIVE_STAGES = ("pose", "measure_depth", "wait_capture", *CAPTURE_STAGES, "incident_light", "render_lightfield",
               "prefilter", "render_view", "composite")
FIRST_CAPTURE_TIMEOUT_S = 600.0     # a decoupled loop waits this long for its first capture
MAX_CHANGES = 4096                  # changes of the synthetic scene kept for the latency


@dataclass
class LiveFrame:
    """One frame of the live loop.

    Attributes:
        index: frame number (0 = the first frame after a start or a reset).
        time_s: the scene time the frame shows, seconds.
        projected_lf: the light field the projector showed while this frame's capture was taken (K, V, U, 3)
            radiance (Ls of the previous frame in the synchronous loop; black at the first frame).
        captured_lf: R, the decoded capture (real point light plus the response to the projection).
        synthetic_lf: Ls_t, what the synthetic scene sends back (the projector shows it from the next capture on).
        real_view: (H, W, 3) float32 view camera radiance under the projection.
        synthetic_view: S_t, the synthetic render with its coverage.
        composite: (H, W, 3) float32, S_t over the real view.
        projected_image: the projector image shown (device integers).
        captured_raw: the LF camera image (device integers).
        clipped_fraction: fraction of lit samples of the projection above the projector's range (clipped).
        moved: whether a synthetic object moved since the previous frame.
        timings_s: seconds per stage of this frame (:data:`LIVE_STAGES`; a decoupled frame has no capture
            stages, its capture's are in ``capture_timings_s``), and "total".
        loop: "sync" or "decoupled".
        scene_version: the synthetic scene's version this frame shows (each pose change or edit adds one).
        light_version: the version of the synthetic scene whose light field lit this frame's capture (-1: the
            black start): a change shows in the real objects' light from the first frame where it is reached.
        capture_index: the capture this frame used.
        capture_age_s: seconds from that capture's moment (the projection shown) to this frame's composite.
        capture_time_s: the scene time the real scene was posed at for that capture, seconds.
        capture_timings_s: that capture's own stages (:data:`CAPTURE_STAGES`).
        started_s, ready_s: ``time.perf_counter()`` when the step began and when the composite was ready.
        interfaces: with several light field interfaces, each one's light this frame (:class:`InterfaceLight`, in
            the scene's order; the fields above without ``interface`` are the first's); empty for one.
    """

    index: int
    time_s: float
    projected_lf: LightField
    captured_lf: LightField
    synthetic_lf: LightField
    real_view: np.ndarray
    synthetic_view: ViewImage
    composite: np.ndarray
    projected_image: np.ndarray
    captured_raw: np.ndarray
    clipped_fraction: float
    moved: bool
    timings_s: dict[str, float] = field(default_factory=dict)
    loop: str = "sync"
    scene_version: int = 0
    light_version: int = -1
    capture_index: int = 0
    capture_age_s: float = 0.0
    capture_time_s: float = 0.0
    capture_timings_s: dict[str, float] = field(default_factory=dict)
    started_s: float = 0.0
    ready_s: float = 0.0
    interfaces: tuple["InterfaceLight", ...] = ()


@dataclass(frozen=True)
class InterfaceLight:
    """One light field interface's light in a live frame of several (:attr:`LiveFrame.interfaces`).

    Attributes:
        projected_lf: what its projector showed during the frame's capture (K, V, U, 3) radiance.
        captured_lf: R, its decoded capture.
        synthetic_lf: Ls_t, what the synthetic scene sends towards its array.
        projected_image: its projector's image (device integers).
        captured_raw: its LF camera's image (device integers).
    """

    projected_lf: LightField
    captured_lf: LightField
    synthetic_lf: LightField
    projected_image: np.ndarray
    captured_raw: np.ndarray


@dataclass(frozen=True)
class FrameTimes:
    """What a long run keeps of a :class:`LiveFrame`: its times and versions, not its images and light fields (the
    rates, the latency and the stage medians need no more; a few hundred whole frames at the paper's resolution hold
    gigabytes, and a process that grows by that much each frame renders slower for it). The fields are the frame's
    own."""

    time_s: float
    timings_s: dict
    capture_index: int
    capture_age_s: float
    capture_time_s: float
    capture_timings_s: dict
    scene_version: int
    light_version: int
    started_s: float
    ready_s: float

    @classmethod
    def of(cls, frame: LiveFrame) -> "FrameTimes":
        return cls(**{name: getattr(frame, name) for name in cls.__dataclass_fields__})


class LiveTransfer:
    """The live loop on any :class:`~lftransfer.rig.base.Rig`.

    Args:
        rig: the rig (simulated, physical or a replay).
        model: what the pipeline knows of the rig (calibrated, or the rig file's nominal values).
        scene: the synthetic part of the scene (its ``animation`` and keyframes move the synthetic objects).
        settings: :class:`~lftransfer.transfer.bounce.TransferSettings` (``bounces``, ``bounce_views`` and
            ``projector_fill`` do not apply: each frame is one exchange).
        projected: the synthetic light field to start from (the state of a resumed sequence), or None: black.
        time_s: the scene time the synthetic side is first posed at.
        depth: (K, V, U) the real scene's depth measured earlier (a resumed sequence's, :attr:`depth`), metres, used
            by the projection prefilter instead of measuring it at the first step; None: measured there.
        loop: "sync" (a capture inside every step) or "decoupled" (captures on their own thread; module
            docstring). A decoupled loop holds a thread: :meth:`close` it (or use it in a ``with``).
        depth_every_frame: measure the real scene's depth at every step, not once (two extra frames each), for
            the depth composite of real objects that move.
        probe: on a scene lit by a light probe, its :class:`~lftransfer.real_depth.probe.ProbeMeasurement` made
            earlier; None: photographed when the loop is made.
        turns: a decoupled loop's captures and frames in turns
            (:class:`~lftransfer.transfer.share.TurnTaking`: the simulator process stopped while a frame renders);
            None: side by side.
        rigs, models: with several light field interfaces, one rig and one rig model per interface in the scene's
            order (``rig`` the first of ``rigs``; :attr:`OpenedRig.rigs` and :attr:`Knowledge.models`); empty for
            one. ``projected`` and ``depth`` are then one per interface, and the composite is the over operator's.

    Example:
        >>> live = LiveTransfer(rig, calibration.model, scene.synthetic_part())      # doctest: +SKIP
        >>> frames = [live.step(t) for t in scene.frame_times()]                      # doctest: +SKIP
    """

    def __init__(self, rig: Rig, model: RigModel, scene: SyntheticScene, settings: TransferSettings = TransferSettings(),
                 *, projected: LightField | Sequence[LightField] | None = None, time_s: float = 0.0,
                 depth: np.ndarray | Sequence[np.ndarray] | None = None, loop: choices.LiveLoop = "sync",
                 depth_every_frame: bool = False, probe=None, turns: TurnTaking | None = None,
                 rigs: Sequence[Rig] = (), models: Sequence[RigModel] = ()) -> None:
        choices.check_choice("loop", loop, choices.LiveLoop)
        self.rigs = list(rigs) or [rig]
        self.models = list(models) or [model]
        if len(self.rigs) != len(self.models) or self.rigs[0] is not rig:
            raise ValueError(f"LiveTransfer: {len(self.rigs)} rigs for {len(self.models)} rig models (rig must be "
                             "the first of rigs)")
        if len(self.rigs) > 1 and settings.composite != "over":
            raise ValueError("several interfaces composite with the over operator (composite = 'over'); the depth "
                             "composite measures one interface's depth")
        self.rig, self.model = rig, self.models[0]
        self.settings = settings
        self.loop = loop
        self.depth_every_frame = bool(depth_every_frame)
        self.turns = turns
        self.sides = SyntheticSide.through(self.models, scene, settings, time_s=time_s)
        self.side = self.sides[0]
        # a light probe's room is still: photographed once (or given, another run's), before the first capture
        self.probe = None
        if scene.probe is not None:
            self.probe = probe if probe is not None else self.side.measure_probe(rig)
            self.side.set_probe(self.probe.radiance)
        U = V = settings.angular_samples
        self._black = Projection(tuple(LightField.zeros(m.array, U, V) for m in self.models), version=-1, black=True)
        self.projection = self._black
        if projected is not None:
            lfs = _each(projected, len(self.rigs), "projected")
            for lf, zero in zip(lfs, self._black.lfs):
                if lf.data.shape != zero.data.shape:
                    raise ValueError(f"projected light field has shape {lf.data.shape}, the loop needs "
                                     f"{zero.data.shape}")
            self.projection = Projection(lfs, version=0)
        self.index = 0
        self.version = 0                         # the synthetic scene's version (pose changes and edits)
        # (version, perf_counter) of the latest changes (a long session keeps the newest MAX_CHANGES)
        self.changes: deque[tuple[int, float]] = deque(maxlen=MAX_CHANGES)
        self._captures = 0
        self._used: tuple[int, int, float] | None = None   # (capture index, version, time) of the last frame
        self._worker: CaptureWorker | None = None
        self._depths: tuple[np.ndarray, ...] | None = None
        self.view_depth: ViewDepth | None = None     # the real depth in the view camera (the depth composite)
        self._plate: np.ndarray | None = None        # the view camera's clean plate (photographed once)
        if depth is not None and settings.measures_depth:
            self._set_depths(_each(depth, len(self.rigs), "depth"))

    @property
    def projected(self) -> LightField:
        """The synthetic light field the (first) projector shows next (black at the start)."""
        return self.projection.lf

    @property
    def projected_lfs(self) -> tuple[LightField, ...]:
        """What each interface's projector shows next, in the scene's order."""
        return self.projection.lfs

    @property
    def depth(self) -> np.ndarray | None:
        """(K, V, U) the real scene's depth the (first interface's) projection prefilter or the depth composite
        uses, metres (NaN: unknown); None before it is measured or when the settings need none."""
        return None if self._depths is None else self._depths[0]

    @property
    def depths(self) -> tuple[np.ndarray, ...] | None:
        """:attr:`depth` of each interface, in the scene's order (each measured with its own projector)."""
        return self._depths

    def _set_depths(self, depths: Sequence[np.ndarray], response: LightField | None = None,
                    photograph: np.ndarray | None = None) -> None:
        """Use ``depths`` (each interface's (K, V, U) metres): for the prefilter, and carried into the view camera
        for the depth composite (one interface; inside the real objects' outline where its white ``response`` and
        the view camera's ``photograph`` with the projector black are given:
        :func:`~lftransfer.real_depth.outline.lightfield_view_depths`)."""
        self._depths = tuple(depths)
        for side, depth in zip(self.sides, self._depths):
            side.set_depth(depth)                    # prefilters only where the settings ask for it
            if side.surface_solve is not None:
                side.surface_solve.live = True       # converge over the frames (surface_solve.WARM_ITERATIONS)
        if self.settings.composite == "depth":
            self.view_depth = lightfield_view_depths(self._depths[0], response, self.model, self.side.scene.view,
                                                     photograph, self._plate, as_it_is=False)[-1]

    @property
    def capture_rate_hz(self) -> float | None:
        """Captures per second of a decoupled loop's worker (None in the synchronous loop)."""
        return None if self._worker is None else self._worker.rate_hz

    def _changed(self, at: float | None = None) -> None:
        self.version += 1
        self.changes.append((self.version, time.perf_counter() if at is None else at))

    def set_scene(self, scene: SyntheticScene, settings: TransferSettings | None = None, *,
                  changed_at: float | None = None) -> None:
        """Change the synthetic scene (an interactive edit) and optionally the settings (lighting model,
        reconstruction, samples; the angular samples stay); the accumulated light carries on.

        Args:
            changed_at: ``time.perf_counter()`` when the change was asked for (for the latency; None: now).
        """
        if settings is not None and settings.angular_samples != self.settings.angular_samples:
            raise ValueError("the angular samples of a running live loop cannot change; start a new one")
        for side in self.sides:                     # the first (which holds the shared renderer) first
            side.set_scene(scene, settings)
        self.settings = self.side.settings
        self._changed(changed_at)

    def reset(self) -> None:
        """Start again from a black projector (the accumulated bounces are dropped)."""
        self.projection = self._black
        self.index = 0
        if self._worker is not None:
            self._worker.show(self._black)

    @contextmanager
    def holding_rigs(self) -> Iterator[list[Rig]]:
        """The rigs (one per interface, in the scene's order) to the caller alone (a decoupled loop's captures wait
        meanwhile)."""
        with (self._worker.holding() if self._worker is not None else nullcontext(self.rigs)) as rigs:
            yield rigs

    @contextmanager
    def captures_paused(self) -> Iterator[None]:
        """A decoupled loop begins no new capture meanwhile (work between frames that is not the live loop's, such
        as writing a sequence's files); nothing waits. The synchronous loop has nothing to pause."""
        with (self._worker.paused() if self._worker is not None else nullcontext()):
            yield

    def hold_captures(self, held: bool) -> None:
        """Begin no new capture until called again with False (a paused page: the rig rests); the synchronous loop
        captures only inside a step anyway."""
        if self._worker is not None:
            self._worker.hold(held)

    def has_news(self, time_s: float) -> bool:
        """Whether a step at ``time_s`` would show anything the last frame did not: always in the synchronous loop
        (every step captures); in the decoupled loop, a new capture, a new scene time or an edit."""
        if self.loop == "sync" or self._used is None or self._worker is None:
            return True
        newest = self._worker.newest()
        index, version, t = self._used
        return (newest is not None and newest.index != index) or version != self.version or \
            (float(time_s) != t and self.side.scene.moving)

    def close(self) -> None:
        """Stop a decoupled loop's capture worker (after the capture in progress)."""
        if self._worker is not None:
            self._worker.stop()
            self._worker = None

    def __enter__(self) -> "LiveTransfer":
        return self

    def __exit__(self, *_exc) -> None:
        self.close()

    def _measure_depth(self) -> None:
        """The real scene's depth for the projection prefilter (``projection == "depth"``) or the depth composite:
        two extra frames per interface, its projector black then white, the others black
        (:func:`~lftransfer.transfer.projection.measure_depth`), and for the depth composite from a view camera on
        the real side a view photograph with the projector black and, the first time, the clean plate (the real
        objects taken away for one photograph: the outline, :mod:`lftransfer.real_depth.outline`). Measured once,
        at the first step: the real objects are taken to stand still (a sequence whose real objects move projects
        the box light field and says so), or at every step with ``depth_every_frame``."""
        side = self.side
        outline = self.settings.composite == "depth" and on_real_side(self.model, side.scene.view)
        U = self.settings.angular_samples
        with self.holding_rigs() as rigs:
            for rig in rigs:
                rig.project(rig.info.black())
            if outline and self._plate is None:
                self._plate = photograph_clean_plate(rigs[0], side.time_s)
            direct = [s.decoder(rig.capture_lf().codes) for s, rig in zip(self.sides, rigs)]
            photograph = rigs[0].capture_view().radiance if outline else None
            swept = []
            for s, model, rig, black in zip(self.sides, self.models, rigs, direct):
                swept.append(measure_depth(rig, s.decoder, s.encoder, model.projector.max_radiance, U, U, black))
                rig.project(rig.info.black())
            self._set_depths([m.depth for m in swept], swept[0].response, photograph)

    def _capture(self, time_s: float, timer: StageTimer) -> Capture:
        sides = self.sides
        coders = ([s.encoder for s in sides], [s.decoder for s in sides])
        peaks = [m.projector.max_radiance for m in self.models]
        if self.loop == "sync":
            cap = capture_once(self.rigs, *coders, self.projection, index=self._captures, real_time_s=time_s,
                               max_radiances=peaks, pose_real=False, timer=timer)
            self._captures += 1
            return cap
        if self._worker is None:
            self._worker = CaptureWorker(self.rigs, *coders, self.projection, max_radiances=peaks,
                                         real_time=lambda: self.side.time_s)
            self._worker.start()
        with timer("wait_capture"):
            cap = self._worker.newest() or self._worker.wait(timeout=FIRST_CAPTURE_TIMEOUT_S)
        return cap

    def _renderer_turn(self):
        """The frame's render in its turn where the captures take turns with it (``turns``); else at once."""
        return self.turns.rendering() if self.turns is not None and self._worker is not None else nullcontext()

    def step(self, time_s: float) -> LiveFrame:
        """Run one frame at scene time ``time_s`` (seconds); see the module docstring."""
        t0 = time.perf_counter()
        bound_blas()        # NumPy's products beside Dr.Jit's kernels: lftransfer.backend
        timer = StageTimer()
        side, s = self.side, self.settings
        with timer("pose"):
            moved = side.pose(time_s)
            for other in self.sides[1:]:
                other.pose(time_s)
        if moved:
            self._changed(t0)
        if self.loop == "sync":
            for rig in self.rigs:
                rig.setup(RealScene(time_s=time_s))
        if s.measures_depth and (self._depths is None or self.depth_every_frame):
            with timer("measure_depth"):
                self._measure_depth()
        cap = self._capture(time_s, timer)
        with self._renderer_turn():
            # the same Monte Carlo seed every frame: a still scene shows a still noise pattern, not a flicker
            with timer("incident_light"):
                lights = [*side.direct_lights, *(each.incident_light(lf, s.seed + 7 * i) for i, (each, lf)
                                                 in enumerate(zip(self.sides, cap.captured_lfs)))]
            sent, view = render_sides(self.sides, lights, s.seed, timer)
            with timer("composite"):
                comp = composite_view(view, cap.real_view, self.view_depth)
        self.projection = Projection(tuple(sent[i] for i in range(len(self.sides))), self.version)
        if self._worker is not None:
            self._worker.show(self.projection)
        ready = time.perf_counter()
        several = () if len(self.sides) == 1 else tuple(
            InterfaceLight(*light) for light in zip(cap.projection.lfs, cap.captured_lfs, self.projection.lfs,
                                                    cap.projected_images, cap.captured_raws))
        frame = LiveFrame(index=self.index, time_s=float(time_s), projected_lf=cap.projection.lf,
                          captured_lf=cap.captured_lf, synthetic_lf=sent[0], real_view=cap.real_view,
                          synthetic_view=view, composite=comp, projected_image=cap.projected_image,
                          captured_raw=cap.captured_raw, clipped_fraction=cap.clipped_fraction, moved=moved,
                          timings_s={**timer.totals, "total": ready - t0}, loop=self.loop,
                          scene_version=self.version, light_version=cap.projection.version,
                          capture_index=cap.index, capture_age_s=ready - cap.started_s,
                          capture_time_s=cap.real_time_s, capture_timings_s=dict(cap.timings_s),
                          started_s=t0, ready_s=ready, interfaces=several)
        self._used = (cap.index, self.version, float(time_s))
        self.index += 1
        return frame


def _each(value, n: int, name: str) -> tuple:
    """``value`` for each of ``n`` interfaces: one value (one interface) or a sequence of ``n``."""
    several = isinstance(value, (list, tuple))
    values = tuple(value) if several else (value,)
    if len(values) != n:
        raise ValueError(f"{name}: {len(values)} given for {n} light field interface(s)")
    return values
