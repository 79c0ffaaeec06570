"""The twin's physical world: the simulated rig's physics behind a clock, for cameras that run at their own rate.

:class:`TwinWorld` holds a :class:`~lftransfer.sim.SimRig` (the hidden real objects, the true lens array, the
point lights, the operator's hand errors) and answers one question for the cameras: what radiance reaches the LF
camera's (or the view camera's) pixels while the projector shows this image, in the set-up of now. Mitsuba runs on
one thread of the world's own (every render is queued there), and a render is kept for the next frames of the
same state, so a camera renders once per change and exposes (adds sensor noise to) every frame.

A set-up (the operator endpoint, :mod:`.server`) is applied once, as it comes, and starts a new *epoch*: a board is
placed with its hidden hand error exactly once, however many frames show it.
"""

from __future__ import annotations

import collections
import hashlib
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from lftransfer.rig.requests import RealScene, Setup, ViewCapture

__all__ = ["TwinWorld"]


def digest(image: np.ndarray) -> str:
    """A short digest of a projector image (the cache key of what it lights)."""
    return hashlib.blake2b(np.ascontiguousarray(image).tobytes(), digest_size=12).hexdigest()


class TwinWorld:
    """The simulated world of a device twin.

    Args:
        world: the scene as it really is (:func:`lftransfer.sim.hidden_world`'s scene: real objects, true lights).
        truth: the true rig model, or None for the rig file's.
        truth_seed: the operator's seed (the hand errors of held boards), as the in-process rig takes it.
        capture_spp: rays per LF camera pixel (None: the simulated rig's default, as ``lft run`` on it).
        view_spp: samples per view camera pixel of the view camera's images (None: the simulated rig's default).
            The in-process rig renders a capture at the samples a request asks for (``ViewCapture.quality``); a
            camera cannot, so the twin renders each state once at this number and a request's ``quality`` becomes
            frames averaged (:class:`~lftransfer.rig.hardware.HardwareRig`).
        keep: renders kept per camera.
    """

    def __init__(self, world, truth, truth_seed: int | None, *, capture_spp: int | None = None,
                 view_spp: int | None = None, keep: int = 6) -> None:
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="twin-render")
        self._lock = threading.Lock()
        self._noise_lock = threading.Lock()
        self._keep = keep
        self._cache: dict[str, collections.OrderedDict] = {"lf": collections.OrderedDict(),
                                                           "view": collections.OrderedDict()}
        self.epoch = 0
        self.setup: Setup = RealScene()
        self.renders = {"lf": 0, "view": 0}
        self.render_s = {"lf": 0.0, "view": 0.0}
        self._shown: str | None = None
        self._moving = bool(getattr(world, "moving", False))

        from lftransfer.sim.oracle import one_interface

        one_interface(world)                       # the twin serves one interface's devices so far

        def build():
            from lftransfer.sim import SimRig

            kwargs = {k: v for k, v in (("capture_spp", capture_spp), ("view_spp", view_spp)) if v is not None}
            return SimRig(world, truth=truth, operator_seed=truth_seed, **kwargs)

        self.sim = self._pool.submit(build).result()
        self.view_spp = self.sim.view_spp
        self.info = self.sim.info

    def arrange(self, request: Setup) -> int:
        """Apply a set-up (once) and start a new epoch; returns the epoch."""
        if isinstance(request, RealScene) and isinstance(self.setup, RealScene) and not self._moving:
            self.setup = request                    # a later moment of a still scene: nothing changes
            return self.epoch

        def apply() -> int:
            self.sim.setup(request)
            with self._lock:
                self.epoch += 1
                self.setup = request
                return self.epoch
        return self._pool.submit(apply).result()

    def radiance(self, camera: str, image: np.ndarray) -> np.ndarray:
        """(H, W, 3) float32 radiance at ``camera``'s pixels ("lf" or "view") while the projector shows ``image``.

        Rendered on the world's thread the first time a state is asked for, then kept.
        """
        key_image = digest(image)

        def render() -> np.ndarray:
            import time

            with self._lock:
                key = (self.epoch, key_image)
            cache = self._cache[camera]
            if key in cache:
                cache.move_to_end(key)
                return cache[key]
            t = time.perf_counter()
            if self._shown != key_image:
                self.sim.project(image)
                self._shown = key_image
            if camera == "lf":
                out = self.sim.lf_signal()
            else:
                out = self.sim.capture_view(ViewCapture(quality=self.view_spp)).radiance
            self.renders[camera] += 1
            self.render_s[camera] += time.perf_counter() - t
            cache[key] = out
            while len(cache) > self._keep:
                cache.popitem(last=False)
            return out
        return self._pool.submit(render).result()

    def expose_lf(self, radiance: np.ndarray) -> np.ndarray:
        """One noisy LF camera frame of ``radiance``: (H, W, 3) uint16 codes."""
        with self._noise_lock:
            return self.sim.expose_lf(radiance, 1)

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)
