"""The live loop of light field transfer (docs/architecture.md, "The bounce loop" and "The live loop"): one capture
and one render per frame.

Frame t, with the projector showing the synthetic light field of frame t - 1 (black at the first frame):

1. pose the synthetic objects at time t (and ask the rig for the real scene at t: the simulated rig moves its
   real objects, a physical one moves by itself);
2. project encode(Ls_{t-1}); capture the LF camera and decode it: R_t, the real scene lit by the real point light
   *and* by Ls_{t-1};
3. capture the view camera (the real view under the same projection);
4. render the synthetic scene lit by its own light (the virtual point light, emitting objects) and by R_t: its
   outgoing light field Ls_t (shown in frame t + 1; prefiltered from the real scene's depth where the settings ask
   for it, the depth measured once before the first frame: :mod:`lftransfer.transfer.projection`) and its view S_t;
5. composite S_t over the real view.

Each frame carries one more exchange than the one before, so for a still scene the frames converge to the
all-bounce fixed point of the bounce loop (:mod:`lftransfer.transfer.bounce`); when something moves the light
follows within a few frames. :meth:`LiveTransfer.step` is the one step function that ``lft render --mode live``,
``lft live`` and ``lft bench`` call.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lftransfer.composite import composite
from lftransfer.lightfield import LightField
from lftransfer.render.renderer import ViewImage
from lftransfer.rig.base import Rig
from lftransfer.rig.model import RigModel
from lftransfer.rig.requests import RealScene
from lftransfer.scenes import SyntheticScene
from lftransfer.transfer.bounce import TransferSettings
from lftransfer.transfer.projection import measure_depth
from lftransfer.transfer.synthetic_side import SyntheticSide
from lftransfer.transfer.timer import StageTimer

__all__ = ["LiveFrame", "LiveTransfer", "LIVE_STAGES"]

LIVE_STAGES = ("pose", "measure_depth", "encode", "capture", "decode", "capture_view", "incident_light",
               "render_lightfield", "prefilter", "render_view", "composite")


@dataclass
class LiveFrame:
    """One frame of the live loop.

    Attributes:
        index: frame number (0 = the first frame after a start or a reset).
        time_s: the scene time the frame shows, seconds.
        projected_lf: Ls_{t-1}, what the projector showed while this frame was captured (K, V, U, 3) radiance.
        captured_lf: R_t, the decoded capture (real point light plus the response to the projection).
        synthetic_lf: Ls_t, what the synthetic scene sends back (the projector shows it next frame).
        real_view: (H, W, 3) float32 view camera radiance under the projection.
        synthetic_view: S_t, the synthetic render with its coverage.
        composite: (H, W, 3) float32, S_t over the real view.
        projected_image: the projector image shown (device integers).
        captured_raw: the LF camera image (device integers).
        clipped_fraction: fraction of lit samples of Ls_{t-1} above the projector's range (clipped).
        moved: whether a synthetic object moved since the previous frame.
        timings_s: seconds per stage (:data:`LIVE_STAGES`), and "total".
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

    Example:
        >>> live = LiveTransfer(rig, calibration.model, scene.synthetic_part())      # doctest: +SKIP
        >>> frames = [live.step(t) for t in scene.frame_times()]                      # doctest: +SKIP
    """

    def __init__(self, rig: Rig, model: RigModel, scene: SyntheticScene, settings: TransferSettings = TransferSettings(),
                 *, projected: LightField | None = None, time_s: float = 0.0,
                 depth: np.ndarray | None = None) -> None:
        self.rig = rig
        self.model = model
        self.settings = settings
        self.side = SyntheticSide(model, scene, settings, time_s=time_s)
        U = V = settings.angular_samples
        self._black_lf = LightField.zeros(model.array, U, V)
        if projected is not None and projected.data.shape != self._black_lf.data.shape:
            raise ValueError(f"projected light field has shape {projected.data.shape}, the loop needs "
                             f"{self._black_lf.data.shape}")
        self.projected = projected if projected is not None else self._black_lf
        self.index = 0
        if depth is not None and settings.prefilters:
            self.side.set_depth(depth)

    @property
    def depth(self) -> np.ndarray | None:
        """(K, V, U) the real scene's depth the projection prefilter uses, metres (NaN: unknown); None before it is
        measured or when the settings do not prefilter."""
        return None if self.side.prefilter is None else self.side.prefilter.depth

    def set_scene(self, scene: SyntheticScene, settings: TransferSettings | None = None) -> None:
        """Change the synthetic scene (an interactive edit) and optionally the settings (lighting model,
        reconstruction, samples; the angular samples stay); the accumulated light carries on."""
        if settings is not None and settings.angular_samples != self.settings.angular_samples:
            raise ValueError("the angular samples of a running live loop cannot change; start a new one")
        self.side.set_scene(scene, settings)
        self.settings = self.side.settings

    def reset(self) -> None:
        """Start again from a black projector (the accumulated bounces are dropped)."""
        self.projected = self._black_lf
        self.index = 0

    def _measure_depth(self) -> None:
        """The real scene's depth for the projection prefilter (``projection == "depth"``): two extra frames,
        projector black then white (:func:`~lftransfer.transfer.projection.measure_depth`). Measured once, at the
        first step: the real objects are taken to stand still (a sequence whose real objects move projects the
        box light field and says so)."""
        rig, side = self.rig, self.side
        rig.project(rig.info.black())
        direct = side.decoder(rig.capture_lf().codes)
        U = self.settings.angular_samples
        side.set_depth(measure_depth(rig, side.decoder, side.encoder, self.model.projector.max_radiance, U, U, direct))

    def step(self, time_s: float) -> LiveFrame:
        """Run one frame at scene time ``time_s`` (seconds); see the module docstring."""
        import time

        t0 = time.perf_counter()
        timer = StageTimer()
        rig, side, s = self.rig, self.side, self.settings
        with timer("pose"):
            moved = side.pose(time_s)
        rig.setup(RealScene(time_s=time_s))
        if side.prefilter is None and s.prefilters:
            with timer("measure_depth"):
                self._measure_depth()
        projected = self.projected
        with timer("encode"):
            pattern = side.encoder(projected) if projected is not self._black_lf else rig.info.black()
        lit = projected.data[projected.data > 0]
        clipped = float(np.mean(lit > self.model.projector.max_radiance)) if lit.size else 0.0
        rig.project(pattern)
        with timer("capture"):
            raw = rig.capture_lf().codes
        with timer("decode"):
            captured = side.decoder(raw)
        with timer("capture_view"):
            real_view = rig.capture_view().radiance
        # the same Monte Carlo seed every frame: a still scene shows a still noise pattern, not a flicker
        with timer("incident_light"):
            lights = [*side.direct_lights, side.incident_light(captured, s.seed)]
        synthetic_lf, view = side.render(lights, s.seed, timer)
        with timer("composite"):
            comp = composite(view.rgb, view.alpha, real_view)
        self.projected = synthetic_lf
        frame = LiveFrame(index=self.index, time_s=float(time_s), projected_lf=projected, captured_lf=captured,
                          synthetic_lf=synthetic_lf, real_view=real_view, synthetic_view=view, composite=comp,
                          projected_image=pattern, captured_raw=raw, clipped_fraction=clipped, moved=moved,
                          timings_s={**timer.totals, "total": time.perf_counter() - t0})
        self.index += 1
        return frame
