"""The state behind ``lft live``: the live loop on its own thread, the edits the page sends, the frames it shows.

The loop thread runs :meth:`lftransfer.transfer.live.LiveTransfer.step` frame after frame and hands each finished
frame to a callback (the server broadcasts it); edits from any page are validated at once (a bad value is refused
with a message, the loop never sees it) and applied between frames, so a change reaches the screen on the next
frame and the page never waits for a render.

In the live loop a frame is one exchange, so its bounces cannot be told apart. On demand (an edit of type
"bounces") the loop thread itself runs the bounce loop (:func:`lftransfer.transfer.interfaces.transfer_through`,
through every light field interface, with ``bounce_views``) on the scene as it stands, between two frames: the live
loop waits meanwhile (one thread uses the rigs) and goes on afterwards as it was (paused or running, its accumulated
light kept), and the per-bounce layers R_n and S_n, each at its own display gain
(:func:`lftransfer.reports.report.bounce_layers`), go to a callback (:class:`ViewerBounces`). Nothing of this runs
unless asked for.
"""

from __future__ import annotations

import base64
import logging
import math
import queue
import threading
import time
from collections import deque
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Callable

import cv2
import numpy as np

from lftransfer.app.viewer.compare import GT_SPP, GroundTruthCompare
from lftransfer.app.viewer.recorder import Recorder
from lftransfer.reports.report import (bounce_layers, device_image, display_scale, emitter_ceiling, interfaces_panel,
                                      live_panel, to_display)
from lftransfer.imageio_utils import to_preview
from lftransfer.render.lights import LIGHTING_MODELS
from lftransfer.rig.base import RigError
from lftransfer.scenes import SceneError, with_overrides
from lftransfer.scenes.interfaces import interface_names
from lftransfer.settings import Overrides, resolve_settings
from lftransfer.transfer.bounce import TransferSettings
from lftransfer.transfer.interfaces import transfer_through
from lftransfer.transfer.latency import motion_latency
from lftransfer.transfer.live import LIVE_STAGES, FrameTimes, LiveFrame, LiveTransfer
from lftransfer.transfer.timer import CoreMeter, rate_hz

__all__ = ["EditError", "LAYERS", "LiveSession", "ViewerBounces", "ViewerFrame"]

log = logging.getLogger(__name__)

LAYERS = ("composite", "panel", "real", "synthetic", "captured", "projected", "depth", "ground truth")
MAX_EXCHANGES = 8          # live steps per shown frame (the page's "bounces"; synchronous loop)
LATENCY_FRAMES = 240       # the latency the page shows is over the changes the last this many frames showed
IDLE_S = 0.005             # a decoupled loop with nothing new to show looks again after this long
_POSE_LIMIT_M = 0.5        # |translate| components the page may ask for, metres


class EditError(ValueError):
    """An edit the page sent that cannot be applied; the message is shown on the page."""


@dataclass
class ViewerFrame:
    """A frame as the page gets it.

    Attributes:
        index: frame number since the start or the last reset.
        time_s: the scene time shown.
        fps: frames per second over the last few frames.
        stages_ms: milliseconds per stage of the last frame (:data:`LIVE_STAGES`) and "total".
        images: layer name -> JPEG bytes (the layers some page asked for).
        clipped_fraction: fraction of lit projected samples above the projector's range.
        loop: "decoupled" or "sync".
        capture_hz: captures per second of the decoupled loop's capture worker (None: synchronous).
        capture_age_s: seconds from the frame's capture to its composite.
        capture_index: the capture the frame used.
        capture_ms: that capture's own stages (encode, capture, decode, capture_view), milliseconds.
        latency_ms: motion-to-composite latency over the recent changes (:func:`motion_latency`): "view" and
            "light", each {"median", "p95", "max", "count"} or None.
        recording: whether the frames are being recorded.
        edits: edits of the synthetic objects applied before this frame was rendered (a page that sent its n-th
            edit sees it from the first frame with ``edits >= n``: edit-to-pixel latency).
        cores_busy: the cores the loop's process and the simulator's keep busy (:class:`CoreMeter`; "simulator"
            None: no simulator process beside the loop), and "turns": the simulator's share of the time where it
            takes turns with the frames (:class:`~lftransfer.transfer.share.TurnTaking`), else None.
    """

    index: int
    time_s: float
    fps: float
    stages_ms: dict[str, float]
    images: dict[str, bytes]
    clipped_fraction: float
    loop: str = "sync"
    capture_hz: float | None = None
    capture_age_s: float = 0.0
    capture_index: int = 0
    capture_ms: dict[str, float] = field(default_factory=dict)
    latency_ms: dict = field(default_factory=dict)
    recording: bool = False
    edits: int = 0
    cores_busy: dict = field(default_factory=dict)

    def message(self, layer: str) -> dict:
        """The JSON message for a page that shows ``layer``."""
        image = self.images.get(layer) or self.images.get("composite", b"")
        return {"type": "frame", "index": self.index, "time_s": round(self.time_s, 3), "fps": round(self.fps, 3),
                "stages_ms": {k: round(v, 1) for k, v in self.stages_ms.items()}, "layer": layer,
                "clipped_fraction": self.clipped_fraction, "loop": self.loop,
                "capture_hz": None if self.capture_hz is None else round(self.capture_hz, 3),
                "capture_age_s": round(self.capture_age_s, 3), "capture_index": self.capture_index,
                "capture_ms": {k: round(v, 1) for k, v in self.capture_ms.items()},
                "latency_ms": self.latency_ms, "recording": self.recording, "edits": self.edits,
                "cores_busy": self.cores_busy,
                "image": "data:image/jpeg;base64," + base64.b64encode(image).decode("ascii")}


@dataclass
class ViewerBounces:
    """The bounce loop's per-bounce layers as the pages get them (or where it stands, or why it failed).

    Attributes:
        state: "running" (sent when it starts and at each of its steps), "done" or "failed".
        bounces: N, the bounces after the direct light.
        time_s: the scene time it ran at, seconds.
        step: what it is doing ("running"), else "".
        elapsed_s: seconds it took ("done", "failed"), while the live loop waited.
        layers: ("done") one dict per layer: side ("real" or "synthetic"), index (bounce n, 0 = direct), gain
            (display gain relative to the direct image), title (as in the Fig. 4 panel) and image (JPEG bytes,
            the view camera's resolution); the real layers of bounces 0..N, then the synthetic ones.
        composite: ("done") JPEG bytes of the final composite, at the direct images' display scale.
        ground_truth: ("done", simulated rig) JPEG bytes of the path-traced ground truth of the same state at the
            same scale, where the "ground truth" layer has one at hand (else empty: none is rendered for this).
        stages_ms: ("done") milliseconds per stage of the bounce loop (summed over its bounces).
        error: ("failed") the reason, as shown on the page.
    """

    state: str
    bounces: int
    time_s: float
    step: str = ""
    elapsed_s: float | None = None
    layers: list[dict] = field(default_factory=list)
    composite: bytes = b""
    ground_truth: bytes = b""
    stages_ms: dict[str, float] = field(default_factory=dict)
    error: str | None = None

    def message(self) -> dict:
        """The JSON message for the pages (images as JPEG data URLs)."""
        def url(data: bytes) -> str:
            return "data:image/jpeg;base64," + base64.b64encode(data).decode("ascii")

        return {"type": "bounces", "state": self.state, "bounces": self.bounces, "time_s": round(self.time_s, 3),
                "step": self.step, "elapsed_s": None if self.elapsed_s is None else round(self.elapsed_s, 3),
                "layers": [{**{k: v for k, v in x.items() if k != "image"}, "image": url(x["image"])}
                           for x in self.layers],
                "composite": url(self.composite) if self.composite else None,
                "ground_truth": url(self.ground_truth) if self.ground_truth else None,
                "stages_ms": {k: round(v, 1) for k, v in self.stages_ms.items()}, "error": self.error}


def _number(payload: dict, key: str, low: float, high: float) -> float:
    """A finite number in [low, high] from the page, or an EditError that says which field and why."""
    value = payload.get(key)
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise EditError(f"{key}: expected a number, got {value!r}") from None
    if not math.isfinite(x):
        raise EditError(f"{key}: expected a finite number, got {value!r}")
    if not low <= x <= high:
        raise EditError(f"{key}: {x:g} is outside [{low:g}, {high:g}]")
    return x


def _vector(payload: dict, key: str, low: float, high: float) -> list[float]:
    values = payload.get(key)
    if not isinstance(values, list) or len(values) != 3:
        raise EditError(f"{key}: expected 3 numbers, got {values!r}")
    return [_number({f"{key}[{i}]": v}, f"{key}[{i}]", low, high) for i, v in enumerate(values)]


@dataclass
class _Pending:
    edits: "queue.Queue[tuple[str, Any]]" = field(default_factory=queue.Queue)


class LiveSession:
    """The live loop of one scene on one rig, driven from web pages.

    Args:
        scene: the whole scene (``SceneConfig``); its real objects are used only through ``sim_rig``.
        live: the live loop (rig, rig model, synthetic part of ``scene``).
        out: folder for saved frames and scenes.
        sim_rig: the simulated rig when there is one (its real objects can be moved), else None.
        oracle: the simulated rig's :class:`~lftransfer.sim.oracle.Oracle` (its hidden world: real objects, true
            light) for the "ground truth" layer, or None.
        lights: the synthetic side's point lights as the rig model knows them (calibrated, or the oracle's), kept
            through every edit; None: the scene file's.
        overrides: what the command asked for beyond the scene file (:class:`~lftransfer.settings.Overrides`):
            an edit from the page changes it and the settings are resolved again for the scene as edited
            (:meth:`resolved`), as ``live`` was built.

    Example:
        >>> session = LiveSession(scene, LiveTransfer(rig, model, scene.synthetic_part()), Path("out/live"))
        >>> session.start(on_frame=print); session.submit({"type": "pause"}); session.stop()   # doctest: +SKIP
    """

    def __init__(self, scene, live: LiveTransfer, out: Path, *, sim_rig=None, oracle=None, lights=None,
                 overrides: Overrides = Overrides()) -> None:
        self.scene = scene
        self.overrides = overrides
        self.oracle = oracle
        self.lights = None if lights is None else list(lights)
        self._gt: tuple[str, np.ndarray] | None = None          # (state key, image) of the latest ground truth
        self._gt_thread: threading.Thread | None = None
        self.live = live
        self.out = Path(out)
        self.sim_rig = sim_rig
        self.interface_names = interface_names(scene.interfaces)      # shown with several interfaces only
        self.paused = False
        self.exchanges = 1
        self.layers: set[str] = {"composite"}
        self.last: LiveFrame | None = None
        self.scale: float | None = None
        self.error: str | None = None
        self.failed: str | None = None                # why the loop ended on its own (the rig failed), one line
        self._pending = _Pending()
        self._stop = threading.Event()
        self._step_once = threading.Event()
        self._thread: threading.Thread | None = None
        self._clock = 0.0
        self._bounces_queued = threading.Event()     # a bounce-layer request waits or runs (one at a time)
        self.last_bounces: ViewerBounces | None = None
        self.edits = 0                                # synthetic object edits applied
        self._recent: deque = deque(maxlen=LATENCY_FRAMES)    # the latest frames' times and versions
        self.recorder = Recorder()
        self._cores = CoreMeter(getattr(live.rig, "cpu_seconds", None))   # the simulator process's, if it has one
        self.compare = GroundTruthCompare(oracle, lambda image, scale: _jpeg(to_display(image, scale), 92)) \
            if oracle is not None else None

    # -- what the page may ask for ------------------------------------------------------------------------------
    def describe(self) -> dict:
        """The page's controls: objects with their current pose and material, settings."""
        def obj(side: str, i: int, o) -> dict:
            m = o.material
            return {"side": side, "index": i, "name": o.name, "translate": list(o.translate),
                    "rotate_deg": list(o.rotate_deg), "material": m.type,
                    "albedo": list(getattr(m, "albedo", [0, 0, 0])), "roughness": getattr(m, "roughness", None),
                    "specular": list(getattr(m, "specular", [0, 0, 0]))}
        objects = [obj("synthetic", i, o) for i, o in enumerate(self.scene.synthetic)]
        if self.sim_rig is not None:
            objects += [obj("real", i, o) for i, o in enumerate(self.sim_rig.real_objects)]
        return {"type": "scene", "objects": objects, "layers": list(LAYERS), "lighting_models": list(LIGHTING_MODELS),
                "lighting_model": self.live.settings.lighting_model, "exchanges": self.exchanges,
                "max_exchanges": MAX_EXCHANGES, "paused": self.paused, "stages": list(LIVE_STAGES),
                "moving": self.scene.moving, "loop": self.live.loop, "compare": self.compare is not None,
                "recording": self.recorder.recording}

    def submit(self, payload: dict) -> dict | None:
        """Check an edit from a page and queue it for the loop; returns an acknowledgement for the page.

        Edits are applied in the order they came, between frames. ``{"type": "bounces"}`` (optionally with
        ``"bounces": N``) asks for the bounce layers (:meth:`bounce_layers`); a second request while one waits
        or runs is acknowledged with ``"queued": False`` and dropped.

        Raises:
            EditError: a malformed or out-of-range edit (nothing is queued).
        """
        if not isinstance(payload, dict) or not isinstance(payload.get("type"), str):
            raise EditError(f"expected an object with a 'type', got {payload!r}")
        kind = payload["type"]
        if kind in ("pause", "resume", "step", "reset", "save"):
            self._pending.edits.put((kind, None))
        elif kind == "compare":
            if self.compare is None:
                raise EditError("compare: the ground truth exists on the simulated rig only")
            if self.compare.busy:
                return {"type": "ack", "edit": kind, "queued": False}
            self._pending.edits.put((kind, None))
        elif kind == "record":
            on = payload.get("on")
            if not isinstance(on, bool):
                raise EditError(f"on: expected true or false, got {on!r}")
            self._pending.edits.put((kind, on))
        elif kind == "exchanges":
            self._pending.edits.put((kind, int(_number(payload, "exchanges", 1, MAX_EXCHANGES))))
        elif kind == "bounces":
            # N: the page's bounce control as it stands when the request's turn comes, unless the request names it
            n = None if payload.get("bounces") is None else int(_number(payload, "bounces", 1, MAX_EXCHANGES))
            if self._bounces_queued.is_set():
                return {"type": "ack", "edit": kind, "queued": False}     # one already waits or runs
            self._bounces_queued.set()
            self._pending.edits.put((kind, n))
        elif kind == "lighting_model":
            model = payload.get("lighting_model")
            try:                       # validated as the command line's --lighting-model is (Overrides)
                if model is None:
                    raise ValueError(f"lighting_model: expected one of {', '.join(LIGHTING_MODELS)}, got nothing")
                Overrides(lighting_model=model)
            except ValueError as exc:
                raise EditError(str(exc)) from None
            self._pending.edits.put((kind, model))
        elif kind == "layer":
            layer = payload.get("layer")
            if layer not in LAYERS:
                raise EditError(f"layer: expected one of {', '.join(LAYERS)}, got {layer!r}")
            self.layers.add(layer)
        elif kind == "object":
            self._pending.edits.put((kind, (*self._object_edit(payload), time.perf_counter())))
        else:
            raise EditError(f"unknown edit type {kind!r}")
        return {"type": "ack", "edit": kind}

    def _object_edit(self, payload: dict) -> tuple[str, int, dict]:
        side = payload.get("side")
        objects = self.scene.synthetic if side == "synthetic" else \
            (self.sim_rig.real_objects if side == "real" and self.sim_rig is not None else None)
        if objects is None:
            raise EditError("side: real objects can be moved on the simulated rig only" if side == "real"
                            else f"side: expected 'synthetic' or 'real', got {side!r}")
        index = payload.get("index")
        if not isinstance(index, int) or not 0 <= index < len(objects):
            raise EditError(f"index: expected 0..{len(objects) - 1}, got {index!r}")
        change: dict[str, Any] = {}
        if "translate" in payload:
            change["translate"] = _vector(payload, "translate", -_POSE_LIMIT_M, _POSE_LIMIT_M)
        if "rotate_deg" in payload:
            change["rotate_deg"] = _vector(payload, "rotate_deg", -360.0, 360.0)
        material = objects[index].material.model_dump()
        for key in ("albedo", "specular"):
            if key in payload:
                if key not in material:
                    raise EditError(f"{key}: a {material['type']} material has no {key}")
                material[key] = _vector(payload, key, 0.0, 1.0)
        if "roughness" in payload:
            if "roughness" not in material:
                raise EditError(f"roughness: a {material['type']} material has no roughness")
            material["roughness"] = _number(payload, "roughness", 0.0, 1.0)
        change["material"] = material
        edited = objects[index].model_dump()
        edited.update(change)
        # validated like a scene file (half-space rule): the message names the object and what is wrong
        try:
            if side == "synthetic":
                with_overrides(self.scene, synthetic=[edited if i == index else o for i, o in enumerate(objects)])
            else:
                with_overrides(self.scene, real=[edited if i == index else o for i, o in enumerate(objects)])
        except SceneError as exc:
            raise EditError(str(exc).split(": ", 1)[-1]) from None
        return side, index, edited

    # -- the loop -----------------------------------------------------------------------------------------------
    def start(self, on_frame: Callable[[ViewerFrame], None], on_error: Callable[[str], None] | None = None,
              on_bounces: Callable[[ViewerBounces], None] | None = None,
              on_message: Callable[[dict], None] | None = None) -> None:
        """Run the loop on its own thread until :meth:`stop`.

        Args:
            on_frame: called (on the loop thread) with every finished frame.
            on_error: called with the message of a frame that failed (the loop goes on).
            on_bounces: called with the bounce layers asked for (:meth:`bounce_layers`): when the bounce loop
                starts, at each of its steps, and when it is done or failed.
            on_message: called with any other message for every page (a comparison with the ground truth, a
                finished recording), from whichever thread made it.
        """
        self._on_frame, self._on_error = on_frame, on_error or (lambda _m: None)
        self._on_bounces = on_bounces or (lambda _b: None)
        self._on_message = on_message or (lambda _m: None)
        self._thread = threading.Thread(target=self._run, name="lft-live-loop", daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 60.0) -> None:
        """Stop the loop after the frame in progress (and its capture worker; a recording is finished)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
        if self.recorder.recording:
            self._on_message(self.recorder.stop().message())
        self.live.close()

    def close(self) -> None:
        """Stop the loop (:meth:`stop`) and release the rig the session was opened with (the simulated rig's
        process, where it has one: :class:`~lftransfer.sim.process.SimulatorProcess`); the session ends here."""
        self.stop()
        self.live.rig.close()

    def _apply(self) -> None:
        while True:
            try:
                kind, value = self._pending.edits.get_nowait()
            except queue.Empty:
                return
            if kind == "pause":
                self.paused = True
            elif kind == "resume":
                self.paused = False
            elif kind == "step":
                self._step_once.set()
            elif kind == "reset":
                self.live.reset()
                self._clock = 0.0
                self._recent.clear()
            elif kind == "exchanges":
                self.exchanges = value
            elif kind == "compare":
                self._request_compare()
            elif kind == "record":
                self._record(value)
            elif kind == "lighting_model":
                self.overrides = replace(self.overrides, lighting_model=value)
                self.live.set_scene(self.synthetic(), self.resolved())
            elif kind == "object":
                side, index, edited, asked_at = value
                if side == "synthetic":
                    objs = list(self.scene.synthetic)
                    objs[index] = edited
                    self.scene = with_overrides(self.scene, synthetic=objs)
                    # a material the fast path does not render takes the exact path: resolved again
                    self.live.set_scene(self.synthetic(), self.resolved(), changed_at=asked_at)
                    self.edits += 1
                else:
                    objs = [o.model_dump() for o in self.sim_rig.real_objects]
                    objs[index] = edited
                    with self.live.holding_rigs():      # not while a capture renders the real scene
                        self.sim_rig.place_real(objs)
            elif kind == "save":
                self.save()
            elif kind == "bounces":
                try:
                    self.last_bounces = self.bounce_layers(value if value is not None else self.exchanges,
                                                           on_step=self._on_bounces)
                finally:
                    self._bounces_queued.clear()
                self._on_bounces(self.last_bounces)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self._apply()
                # a paused page rests the rig too (a decoupled loop would go on capturing); a step captures anew
                self.live.hold_captures(self.paused and not self._step_once.is_set())
                if self.paused and not self._step_once.is_set():
                    time.sleep(0.02)
                    continue
                t = self._time_next()
                if not self._step_once.is_set() and not self.live.has_news(t):
                    time.sleep(IDLE_S)           # decoupled: nothing new until the next capture or edit
                    continue
                self._step_once.clear()
                # each synchronous step is one exchange; a decoupled step renders the newest capture once
                for _ in range(self.exchanges if self.live.loop == "sync" else 1):
                    frame = self.live.step(t)
                self._clock += 1
                self.last = frame
                self._recent.append(FrameTimes.of(frame))
                self._on_frame(self._viewer_frame(frame))
            except RigError as exc:      # the rig is gone (a dead simulator, a device fault): the loop ends here
                self.error = self.failed = f"the live loop stopped: {exc}"
                log.error("%s", self.failed)
                self._on_error(self.error)
                return
            except Exception as exc:  # noqa: BLE001 - the loop keeps running; the page shows why a frame failed
                self.error = f"{type(exc).__name__}: {exc}"
                self._on_error(self.error)
                time.sleep(0.5)

    def _time_next(self) -> float:
        """The scene time of the next frame, seconds (0 for a still scene)."""
        times = self.scene.frame_times()
        return float(times[int(self._clock) % len(times)]) if self.scene.moving else 0.0

    def resolved(self, *, bounces: int | None = None, bounce_views: bool | None = None) -> TransferSettings:
        """The live loop's settings for the scene as it now is: :attr:`overrides` (with ``bounces`` for a run of
        the bounce loop) resolved as ``lft live`` resolved them (:func:`~lftransfer.settings.resolve_settings`,
        ``live``), so a page's edit is validated and made final the same way as the command line's."""
        asked = self.overrides if bounces is None else replace(self.overrides, bounces=bounces)
        views = self.live.settings.bounce_views if bounce_views is None else bounce_views
        return resolve_settings(self.scene, asked, live=True, bounce_views=views).transfer

    def bounce_layers(self, bounces: int, *, on_step: Callable[[ViewerBounces], None] | None = None) -> ViewerBounces:
        """Run the bounce loop on the scene as it stands and return its per-bounce layers; never raises.

        The scene as it stands: the synthetic objects as edited, the real ones where the page put them (simulated
        rig), the time of the frame on the screen, the live loop's rig, rig model and settings (lighting model,
        samples). Call it only from the loop's thread (:meth:`submit` ``{"type": "bounces"}`` from elsewhere), or
        while the loop does not run: it uses the rig. The live loop's state (its projected light field, frame
        count, pause) is left as it was; the next live frame projects that light field again.

        Args:
            bounces: N >= 1, exchanges after the direct light.
            on_step: called with a "running" :class:`ViewerBounces` as it starts and at each step; a stop of the
                session (:meth:`stop`) aborts the run at the next step.

        Returns:
            "done" with the real layers R_n (``Bounce.real_view``) and the synthetic ones S_n for n = 0..N, their
            display gains relative to the direct image and the composite; or "failed" with the reason (a rig
            error, a render error, the session stopped).
        """
        step = on_step or (lambda _b: None)
        t = self.last.time_s if self.last is not None else self._time_next()
        settings = self.resolved(bounces=int(bounces), bounce_views=True)
        t0 = time.perf_counter()

        def progress(message: str) -> None:
            if self._stop.is_set():
                raise RuntimeError("the session stopped")
            step(ViewerBounces("running", settings.bounces, t, step=message))

        try:
            progress("starting")
            with self.live.holding_rigs() as rigs:       # a decoupled loop's captures wait meanwhile
                result = transfer_through(rigs, self.live.models, self.synthetic(), settings, progress=progress,
                                          time_s=t)
            comp = result.composite()
            layers = bounce_layers(result, comp, ceiling=emitter_ceiling(self.scene))
            base = layers[0].scale                        # the direct images' display scale
            gt = self._gt                                 # the ground truth at hand, if it shows this very state
            if gt is not None and gt[0] != self._world_now(t).model_dump_json(exclude={"source"}):
                gt = None
            return ViewerBounces(
                "done", settings.bounces, t, elapsed_s=time.perf_counter() - t0,
                layers=[{"side": x.side, "index": x.index, "gain": x.gain, "title": x.title,
                         "image": _jpeg(x.image, 92)} for x in layers],
                composite=_jpeg(to_display(np.clip(comp, 0, None), base), 92),
                ground_truth=_jpeg(to_display(gt[1], base), 92) if gt is not None else b"",
                stages_ms={k: 1000.0 * v for k, v in result.timings_s.items()})
        except Exception as exc:  # noqa: BLE001 - shown on the page; the live loop goes on
            error = f"bounce layers failed: {type(exc).__name__}: {exc}"
            log.warning("%s", error, exc_info=True)
            return ViewerBounces("failed", settings.bounces, t, elapsed_s=time.perf_counter() - t0, error=error)

    def _viewer_frame(self, frame: LiveFrame) -> ViewerFrame:
        if self.scale is None:
            self.scale = display_scale(frame.composite, ceiling=emitter_ceiling(self.scene))
        wanted = self.layers | ({"composite"} if self.recorder.recording else set())
        shown = {layer: self._layer(frame, layer) for layer in wanted}    # each display image made once
        images = {layer: _jpeg(shown[layer]) for layer in self.layers}
        if self.recorder.recording:
            self.recorder.add(shown["composite"])
        fps = rate_hz([r.ready_s for r in self._recent])
        latency = motion_latency(list(self.live.changes), list(self._recent), self.live.loop)
        return ViewerFrame(index=frame.index, time_s=frame.time_s, fps=fps,
                           stages_ms={k: 1000.0 * v for k, v in frame.timings_s.items()}, images=images,
                           clipped_fraction=frame.clipped_fraction, loop=frame.loop,
                           capture_hz=self.live.capture_rate_hz, capture_age_s=frame.capture_age_s,
                           capture_index=frame.capture_index,
                           capture_ms={k: 1000.0 * v for k, v in frame.capture_timings_s.items()},
                           latency_ms={"view": latency.view and asdict(latency.view),
                                       "light": latency.light and asdict(latency.light)},
                           recording=self.recorder.recording, edits=self.edits,
                           cores_busy={**self._cores.sample(), "turns": self.live.turns and self.live.turns.share})

    def _request_compare(self) -> None:
        """Start the ground truth of the frame on the screen (:class:`GroundTruthCompare`); the page hears when
        it is ready."""
        frame = self.last
        if frame is None:
            self._on_message({"type": "compare", "error": "no frame to compare yet"})
            return
        started = self.compare.request(frame.index, frame.time_s, frame.composite, self._world_now(frame.time_s),
                                       self.scale or 1.0, lambda c: self._on_message(c.message()))
        self._on_message({"type": "compare", "state": "running" if started else "busy",
                          "frame_index": frame.index, "time_s": round(frame.time_s, 3)})

    def _record(self, on: bool) -> None:
        """Start or stop recording the shown composites to ``out/record-STAMP.mp4``."""
        if on and not self.recorder.recording:
            path = self.out / f"record-{time.strftime('%Y%m%d-%H%M%S')}.mp4"
            fps = max(1, round(rate_hz([r.ready_s for r in self._recent])))
            self.recorder.start(path, fps)
            self._on_message({"type": "recording", "path": str(path), "fps": fps})
        elif not on and self.recorder.recording:
            self._on_message(self.recorder.stop().message())

    def synthetic(self):
        """The synthetic part of the scene as it stands (edited), its point lights where the rig model has them."""
        part = self.scene.synthetic_part()
        return part if self.lights is None else with_overrides(part, lights=self.lights)

    def _world_now(self, t: float):
        """The simulated world as it stands now: the real objects (moved by the page), the synthetic ones (edited),
        the true light, posed at ``t``."""
        world = self.oracle.world
        real = self.sim_rig.real_objects if self.sim_rig is not None else world.real
        return with_overrides(world, real=real, synthetic=list(self.scene.synthetic)).at(t)

    def _ground_truth(self, frame: LiveFrame) -> np.ndarray | None:
        """The path-traced ground truth of the current state beside the composite: rendered on its own thread
        at :data:`GT_SPP` samples per pixel whenever the state changed, the latest finished one shown."""
        if self.oracle is None:
            return None
        world = self._world_now(frame.time_s)
        key = world.model_dump_json(exclude={"source"})
        if (self._gt is None or self._gt[0] != key) and (self._gt_thread is None or not self._gt_thread.is_alive()):
            def render() -> None:
                self._gt = (key, self.oracle.ground_truth(spp=GT_SPP, world=world, use_cache=False).image)
            self._gt_thread = threading.Thread(target=render, name="lft-live-gt", daemon=True)
            self._gt_thread.start()
        return self._gt[1] if self._gt is not None else None

    def _layer(self, frame: LiveFrame, layer: str) -> np.ndarray:
        """The display image of ``layer`` (sRGB through :func:`~lftransfer.imageio_utils.to_preview`'s table: within
        one code of the written images' :func:`~lftransfer.imageio_utils.to_display`, five times faster)."""
        rig = self.scene.rig
        if layer == "ground truth":
            gt = self._ground_truth(frame)
            left = to_preview(np.clip(frame.composite, 0, None), self.scale)
            right = to_preview(gt, self.scale) if gt is not None else np.zeros_like(left)
            return np.concatenate([left, right], axis=1)
        if layer == "panel":
            return live_panel(frame, None, self.scale, camera_bits=rig.lf_camera_bits,
                              projector_bits=rig.projector_bits, tile_width=320, names=self.interface_names)
        if layer == "real":
            return to_preview(np.clip(frame.real_view, 0, None), self.scale)
        if layer == "synthetic":
            return to_preview(np.clip(frame.synthetic_view.rgb, 0, None), self.scale)
        if layer in ("captured", "projected") and frame.interfaces:     # several interfaces: a row for each
            return interfaces_panel([x.projected_image for x in frame.interfaces], self.interface_names,
                                    [x.captured_raw for x in frame.interfaces], rig.lf_camera_bits,
                                    titles=("its LF camera (captured)", "its projector (previous Ls)"))
        if layer == "captured":
            return device_image(frame.captured_raw, rig.lf_camera_bits, stretch=True)
        if layer == "projected":
            return device_image(frame.projected_image, rig.projector_bits)
        if layer == "depth":
            return depth_layer(self.live.view_depth, frame.synthetic_view.depth)
        return to_preview(np.clip(frame.composite, 0, None), self.scale)

    def save(self) -> list[Path]:
        """Write the current frame (EXR and PNG) and the current scene (TOML) into the output folder."""
        from lftransfer.imageio_utils import write_exr, write_png, write_text

        frame = self.last
        self.out.mkdir(parents=True, exist_ok=True)
        stamp = time.strftime("%Y%m%d-%H%M%S")
        files = [write_text(self.out / f"scene-{stamp}.toml", scene_toml(self.scene))]
        if frame is not None:
            files += [write_exr(self.out / f"frame-{stamp}.exr", frame.composite),
                      write_png(self.out / f"frame-{stamp}.png", to_display(frame.composite, self.scale or 1.0))]
        return files


def depth_layer(real, synthetic_depth: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 the page's "depth" layer: the real scene's depth in the view camera that the depth composite
    uses (``real``: :class:`~lftransfer.real_depth.ViewDepth`, or None with the over composite) in orange, beside
    the synthetic render's depth in blue; nearer is brighter, one scale for both (the nearest to the farthest
    of either), black where a side has none.

    Args:
        real: the real depth, or None.
        synthetic_depth: (H, W) metres along each view ray to the synthetic objects (inf where none).
    """
    syn = np.where(np.isfinite(synthetic_depth), synthetic_depth, np.nan)
    rd = np.full(syn.shape, np.nan) if real is None else np.asarray(real.depth, np.float64)
    both = np.concatenate([syn[np.isfinite(syn)], rd[np.isfinite(rd)]])
    tiles = []
    for d, colour in ((rd, (1.0, 0.55, 0.1)), (syn, (0.3, 0.6, 1.0))):
        if both.size:
            near, far = float(both.min()), float(both.max())
            nearness = (far - np.nan_to_num(d, nan=far)) / max(far - near, 1e-9)
            level = np.where(np.isfinite(d), 0.25 + 0.75 * nearness, 0.0)
        else:
            level = np.zeros(d.shape)
        tiles.append((level[..., None] * np.asarray(colour)[None, None] * 255).astype(np.uint8))
    return np.concatenate(tiles, axis=1)


def scene_toml(scene) -> str:
    """The scene as a TOML file that :func:`lftransfer.scenes.load_scene` reads back."""
    import tomli_w

    data = scene.model_dump(mode="json", exclude={"source"}, exclude_none=True)
    if "lights" in data:                            # the file's table is [[light]] (the model calls them lights)
        data["light"] = data.pop("lights")
    for side in ("real", "synthetic"):
        for o in data.get(side, []):
            if not o.get("keyframes"):
                o.pop("keyframes", None)
    return tomli_w.dumps(data)


def _jpeg(image: np.ndarray, quality: int = 88) -> bytes:
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(np.ascontiguousarray(image[..., :3]), cv2.COLOR_RGB2BGR),
                           [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise RuntimeError("JPEG encoding failed")
    return buf.tobytes()
