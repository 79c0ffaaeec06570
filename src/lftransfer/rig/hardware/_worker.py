"""A daemon thread that runs device calls one at a time, so a caller can wait for each with a time limit.

Device libraries block: ``cv2.VideoCapture.read`` waits for the driver as long as the driver likes, and a GLFW
window belongs to the thread that made it. Every call to such a device therefore goes through one
:class:`Worker`: the caller waits for the answer at most ``timeout`` seconds. A call that overruns cannot be
interrupted (Python cannot kill a thread); the worker is then *stuck*: later calls fail at once with
:class:`WorkerStuck` until the overrunning call returns by itself. The thread is a daemon, so a device that
never answers cannot keep the interpreter from exiting.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from concurrent.futures import Future
from concurrent.futures import TimeoutError as _FutureTimeout
from typing import Any, Callable

__all__ = ["Worker", "WorkerStuck", "WorkerTimeout"]

_log = logging.getLogger(__name__)


class WorkerTimeout(TimeoutError):
    """A call did not return within its time limit (the worker is stuck from now on)."""


class WorkerStuck(RuntimeError):
    """The worker is still inside an earlier call that overran its time limit."""


class Worker:
    """One daemon thread executing submitted calls in order.

    Args:
        name: thread name (shows in logs and debuggers).
        idle: called on the worker thread every ``idle_s`` seconds while no call is queued (e.g. to process a
            window's events), or None.
        idle_s: period of ``idle``, seconds.
    """

    def __init__(self, name: str, idle: Callable[[], None] | None = None, idle_s: float = 0.1) -> None:
        self.name = name
        self._idle = idle
        self._idle_s = idle_s
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self._stuck: tuple[str, float] | None = None     # (what, since monotonic time)
        self._stopped = False

    # -- the thread -------------------------------------------------------------------------------------------

    def _run(self) -> None:
        while True:
            try:
                job = self._queue.get(timeout=self._idle_s) if self._idle else self._queue.get()
            except queue.Empty:
                try:
                    self._idle()  # type: ignore[misc]
                except Exception:  # noqa: BLE001  (an idle hook must not end the thread)
                    _log.debug("%s: idle hook failed", self.name, exc_info=True)
                continue
            if job is None:
                return
            fn, args, kwargs, future = job
            if not future.set_running_or_notify_cancel():
                continue
            try:
                result = fn(*args, **kwargs)
            except BaseException as exc:  # noqa: BLE001  (handed to the caller)
                future.set_exception(exc)
            else:
                future.set_result(result)
            finally:
                with self._lock:
                    if self._stuck is not None:
                        _log.info("%s: the call that overran (%s) returned after %.1f s", self.name,
                                  self._stuck[0], time.monotonic() - self._stuck[1])
                        self._stuck = None

    def _ensure_thread(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name=self.name, daemon=True)
            self._thread.start()

    # -- calls ------------------------------------------------------------------------------------------------

    @property
    def stuck(self) -> tuple[str, float] | None:
        """(what, seconds since) of the call that overran and has not returned yet, or None."""
        with self._lock:
            if self._stuck is None:
                return None
            return self._stuck[0], time.monotonic() - self._stuck[1]

    def call(self, fn: Callable[..., Any], *args: Any, timeout: float, what: str, **kwargs: Any) -> Any:
        """Run ``fn(*args, **kwargs)`` on the worker thread and wait for its result.

        Args:
            fn: the call.
            timeout: seconds to wait for it, > 0.
            what: what the call does, for messages ("reading a frame").

        Returns:
            What ``fn`` returned; an exception it raised is raised here.

        Raises:
            WorkerTimeout: ``fn`` did not return within ``timeout`` (it goes on in the background).
            WorkerStuck: an earlier call is still running past its limit.
        """
        with self._lock:
            if self._stopped:
                raise RuntimeError(f"{self.name}: the worker was stopped")
            if self._stuck is not None:
                since = time.monotonic() - self._stuck[1]
                raise WorkerStuck(f"still blocked in {self._stuck[0]} (for {since:.1f} s)")
            self._ensure_thread()
        future: Future = Future()
        self._queue.put((fn, args, kwargs, future))
        try:
            return future.result(timeout=timeout)
        except _FutureTimeout:
            if future.cancel():           # it had not started: nothing is stuck
                raise WorkerTimeout(f"{what} did not start within {timeout:g} s") from None
            with self._lock:
                if not future.done():
                    self._stuck = (what, time.monotonic())
            if future.done():
                return future.result()
            raise WorkerTimeout(f"{what} did not return within {timeout:g} s") from None

    def stop(self) -> None:
        """Let the thread end once it has done the queued calls (idempotent)."""
        with self._lock:
            if self._stopped:
                return
            self._stopped = True
        if self._thread is not None:
            self._queue.put(None)
