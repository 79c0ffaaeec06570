"""The projector as the twin sees it: what the window system shows on the projector's monitor, over time.

:class:`ProjectorScreen` reads the monitor's pixels from the X server (:class:`lftransfer.rig.x11.XScreen`)
at the display's refresh rate and keeps the moments they changed, so a camera frame taken at time t can show the
image that was on the screen at t minus the display-to-capture latency. It sees whatever the window system drew
(a window in the wrong place, a half-drawn frame, a desktop where no window is), not what the pipeline meant.

:func:`start_xvfb` starts a private virtual X server of the projector's size when no display is given.
"""

from __future__ import annotations

import bisect
import logging
import os
import shutil
import subprocess
import threading
import time

import numpy as np

from lftransfer.rig.x11 import XScreen
from lftransfer.sim.twin.world import digest

__all__ = ["ProjectorScreen", "start_xvfb"]

_log = logging.getLogger(__name__)


def start_xvfb(width: int, height: int, timeout_s: float = 10.0) -> tuple[str, subprocess.Popen]:
    """Start Xvfb with one ``width`` x ``height`` x 24 screen; returns (":N", the process).

    Raises:
        RuntimeError: Xvfb is not installed or did not start.
    """
    exe = shutil.which("Xvfb")
    if exe is None:
        raise RuntimeError("Xvfb is not installed (scripts/bootstrap.sh installs Debian's xvfb); or give --display")
    read_fd, write_fd = os.pipe()
    proc = subprocess.Popen([exe, "-displayfd", str(write_fd), "-screen", "0", f"{width}x{height}x24",
                             "-nolisten", "tcp", "-noreset"], pass_fds=(write_fd,),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(write_fd)
    number = b""
    deadline = time.monotonic() + timeout_s
    try:
        os.set_blocking(read_fd, False)
        while not number.endswith(b"\n") and time.monotonic() < deadline and proc.poll() is None:
            try:
                chunk = os.read(read_fd, 64)
            except BlockingIOError:
                time.sleep(0.02)
                continue
            if not chunk:
                break
            number += chunk
    finally:
        os.close(read_fd)
    if not number.strip().isdigit():
        proc.kill()
        raise RuntimeError("Xvfb did not start")
    return f":{number.strip().decode()}", proc


class ProjectorScreen:
    """The projector's monitor, read from an X display.

    Args:
        x_display: the X display (":N").
        size: (width, height) of the projector, pixels (the region read, from ``origin``).
        origin: (x, y) of the projector's top-left pixel on the screen (several projectors side by side on one
            screen: the rig file's ``projector.x``, ``y``).
        bits: the projector's bit depth (the screen's 8-bit channels are scaled to it).
        refresh_hz: how often the screen is read (a projector's refresh rate).
        missing: the projector is unplugged: the screen is never read, the projector shows black.

    Raises:
        RuntimeError: the display cannot be opened, or its screen is smaller than the projector.
    """

    KEEP = 256                       # screen changes remembered

    def __init__(self, x_display: str, size: tuple[int, int], bits: int = 8, refresh_hz: float = 60.0,
                 missing: bool = False, origin: tuple[int, int] = (0, 0)) -> None:
        self.size = (int(size[0]), int(size[1]))
        self.origin = (int(origin[0]), int(origin[1]))
        self.bits = int(bits)
        self._period = 1.0 / refresh_hz
        black = np.zeros((self.size[1], self.size[0], 3), np.uint8 if bits <= 8 else np.uint16)
        self._times = [time.monotonic() - 3600.0]
        self._images = [(digest(black), black)]
        self._lock = threading.Condition()
        self._stop = threading.Event()
        self._seen_until = -float("inf")    # the screen is known up to here (the last look's end)
        self.changes = 0
        self.error: str | None = None
        self._thread = None
        if missing:
            return
        screen = XScreen(x_display)
        if screen.size[0] < self.origin[0] + self.size[0] or screen.size[1] < self.origin[1] + self.size[1]:
            screen.close()
            raise RuntimeError(f"the X display {x_display} is {screen.size[0]}x{screen.size[1]}, smaller than the "
                               f"projector's {self.size[0]}x{self.size[1]} at {self.origin}")
        self._thread = threading.Thread(target=self._watch, args=(screen,), name="twin-projector", daemon=True)
        self._thread.start()

    def _codes(self, rgb8: np.ndarray) -> np.ndarray:
        if self.bits <= 8:
            return rgb8
        return np.round(rgb8.astype(np.float64) * (((1 << self.bits) - 1) / 255.0)).astype(np.uint16)

    def _watch(self, screen: XScreen) -> None:
        last = None
        next_t = time.monotonic()
        try:
            while not self._stop.is_set():
                try:
                    rgb = screen.grab(*self.size, *self.origin)
                except RuntimeError as exc:
                    with self._lock:
                        self.error = str(exc)
                        self._lock.notify_all()
                    _log.warning("projector screen: %s", exc)
                    self._stop.wait(0.5)
                    continue
                t = time.monotonic()
                changed = last is None or not np.array_equal(rgb, last)
                if changed:
                    last = rgb
                    codes = self._codes(rgb)
                    entry = (digest(codes), codes)
                with self._lock:
                    if changed:
                        self._times.append(t)
                        self._images.append(entry)
                        if len(self._times) > self.KEEP:
                            del self._times[0], self._images[0]
                        self.changes += 1
                    self._seen_until = t
                    self.error = None
                    self._lock.notify_all()
                next_t = max(next_t + self._period, time.monotonic())
                self._stop.wait(max(0.0, next_t - time.monotonic()))
        finally:
            screen.close()

    WAIT_S = 1.0                     # longest wait for the screen to be looked at after the moment asked for

    def at(self, t: float) -> tuple[str, np.ndarray]:
        """(digest, (H, W, 3) projector codes) of what the screen showed at monotonic time ``t``.

        What the screen showed at ``t`` is known once it has been looked at after ``t``: a past moment the watcher
        has not reached yet (it fell behind on a loaded machine) waits for its next look, up to :attr:`WAIT_S`, so
        a camera frame never shows an image that had already been replaced at its moment. A moment still to come
        is answered as the present (nobody waits for the future). Without a watcher (a missing projector) or after
        a failed look, the last image known is the answer."""
        t = min(t, time.monotonic())
        with self._lock:
            if self._thread is not None and self.error is None:
                self._lock.wait_for(lambda: self._seen_until >= t or self._stop.is_set() or self.error is not None,
                                    timeout=self.WAIT_S)
            i = bisect.bisect_right(self._times, t) - 1
            return self._images[max(i, 0)]

    def close(self) -> None:
        self._stop.set()
        with self._lock:
            self._lock.notify_all()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
