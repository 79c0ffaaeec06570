"""The twin's physical world: the simulated rig's physics behind a clock, for cameras that run at their own rate.

:class:`TwinWorld` holds a :class:`~lftransfer.sim.SimRig` per light field interface (one world:
:class:`~lftransfer.sim.interfaces.SimInterfaces`; the hidden real objects, the true lens arrays, the point lights,
the operator's hand errors) and answers one question for the cameras: what radiance reaches an LF camera's (or the
view camera's) pixels while the projectors show these images, in the set-up of now. Mitsuba runs on one thread of
the world's own (every render is queued there), and a render is kept for the next frames of the same state, so a
camera renders once per change and exposes (adds sensor noise to) every frame.

A set-up (an interface's operator endpoint, :mod:`.server`) is applied once, as it comes, and starts a new *epoch*:
a board is placed with its hidden hand error exactly once, however many frames show it. The simulator places an
interface's boards in that interface's own copy of the world, so the one view camera shows the copy of the
interface last asked for a set-up other than the real scene (the first's while every one shows the real scene).
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
        truths: with several light field interfaces (the world's ``[[interface]]`` tables), each one's true rig
            model (:func:`lftransfer.sim.truth.true_interfaces`), or None: each one's nominal model.
    """

    def __init__(self, world, truth, truth_seed: int | None, *, capture_spp: int | None = None,
                 view_spp: int | None = None, keep: int = 6, truths=None) -> None:
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="twin-render")
        self._lock = threading.Lock()
        self._noise_lock = threading.Lock()
        self._keep = keep
        n = max(1, len(getattr(world, "interfaces", ())))
        self.cameras = ["view", *(f"lf{i}" for i in range(n))]
        self._cache: dict[str, collections.OrderedDict] = {name: collections.OrderedDict() for name in self.cameras}
        self.epoch = 0
        self.setups: list[Setup] = [RealScene()] * n
        self.viewer = 0                           # the interface whose copy of the world the view camera shows
        self.renders = {name: 0 for name in self.cameras}
        self.render_s = {name: 0.0 for name in self.cameras}
        self._shown: list[str | None] = [None] * n
        self._moving = bool(getattr(world, "moving", False))

        def build():
            from lftransfer.sim.interfaces import SimInterfaces

            kwargs = {k: v for k, v in (("capture_spp", capture_spp), ("view_spp", view_spp)) if v is not None}
            return SimInterfaces(world, truths=truths if n > 1 else [truth], operator_seed=truth_seed, **kwargs).rigs

        self.sims = self._pool.submit(build).result()
        self.view_spp = self.sims[0].view_spp
        self.infos = [rig.info for rig in self.sims]
        self.info = self.infos[0]

    @property
    def setup(self) -> Setup:
        """The set-up the view camera shows (its interface's)."""
        return self.setups[self.viewer]

    def arrange(self, request: Setup, interface: int = 0) -> int:
        """Apply a set-up through interface ``interface`` (once) and start a new epoch; returns the epoch."""
        if isinstance(request, RealScene) and isinstance(self.setups[interface], RealScene) and not self._moving:
            self.setups[interface] = request        # a later moment of a still scene: nothing changes
            return self.epoch

        def apply() -> int:
            self.sims[interface].setup(request)
            with self._lock:
                self.epoch += 1
                self.setups[interface] = request
                if not isinstance(request, RealScene):
                    self.viewer = interface
                elif self.viewer == interface:
                    self.viewer = 0
                return self.epoch
        return self._pool.submit(apply).result()

    def radiance(self, camera: str, images) -> np.ndarray:
        """(H, W, 3) float32 radiance at ``camera``'s pixels ("view", or "lf0", "lf1", ...: interface i's LF camera)
        while the projectors show ``images`` (one per interface, in order).

        Rendered on the world's thread the first time a state is asked for, then kept.
        """
        key_images = tuple(digest(image) for image in images)

        def render() -> np.ndarray:
            import time

            with self._lock:
                key = (self.epoch, key_images)
                viewer = self.viewer
            cache = self._cache[camera]
            if key in cache:
                cache.move_to_end(key)
                return cache[key]
            t = time.perf_counter()
            for i, (rig, image, k) in enumerate(zip(self.sims, images, key_images)):
                if self._shown[i] != k:
                    rig.project(image)
                    self._shown[i] = k
            if camera == "view":
                out = self.sims[viewer].capture_view(ViewCapture(quality=self.view_spp)).radiance
            else:
                out = self.sims[int(camera[2:])].lf_signal()
            self.renders[camera] += 1
            self.render_s[camera] += time.perf_counter() - t
            cache[key] = out
            while len(cache) > self._keep:
                cache.popitem(last=False)
            return out
        return self._pool.submit(render).result()

    def expose_lf(self, radiance: np.ndarray, interface: int = 0) -> np.ndarray:
        """One noisy frame of interface ``interface``'s LF camera of ``radiance``: (H, W, 3) uint16 codes."""
        with self._noise_lock:
            return self.sims[interface].expose_lf(radiance, 1)

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)
