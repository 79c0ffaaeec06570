"""The projector: a borderless full-screen window on one monitor that shows an image pixel for pixel.

Why GLFW (the ``glfw`` wheel) with PyOpenGL:

- the ``glfw`` wheel ships ``libglfw`` itself (X11 and Wayland builds), so the only system libraries needed are
  the window system's and ``libGL.so.1``: on a headless test machine Debian's Xvfb and Mesa's software OpenGL
  (``scripts/bootstrap.sh``); PyOpenGL is pure Python (ctypes). Nothing compiles at install time.
- GLFW exposes exactly what a projector needs and nothing that gets in the way: monitors by index with their
  video modes, full-screen on a chosen monitor without a mode switch ("windowed full screen": the window takes the
  monitor's current mode), no auto-iconify when the operator's terminal takes the focus, a swap interval
  (vsync), and the native X11 handles used by :meth:`ProjectorWindow.screenshot`. pyglet or moderngl-window
  would bring their own event loop, projection and scaling conventions (pyglet's HiDPI scaling,
  moderngl-window's viewport fitting) that would have to be undone to stay pixel-exact.

Pixel exactness: the image is uploaded to a texture of the projector's size and copied to the window's back
buffer with ``glBlitFramebuffer`` (same size, ``GL_NEAREST``: no scaling, no filtering), with dithering, blending,
sRGB conversion and multisampling off; the framebuffer must be exactly ``width`` x ``height`` (a HiDPI scale or a
monitor in another mode is a :class:`~lftransfer.rig.base.RigError`). Where the monitor's gamma ramp is not the
identity (a night light, a calibration profile) it is set to the identity while the window is open (GLFW
restores the old ramp when the last window closes), so the codes reach the projector unchanged.

Bit depth: an 8-bit projector takes (H, W, 3) uint8 images. A projector of 9 to 16 bits takes uint16 codes of
that many bits: they are scaled to 16-bit full scale (code * 65535 / (2^bits - 1)), uploaded to a 16-bit texture,
and the window asks for a framebuffer of ``bits`` bits per channel; where the display gives fewer (most give 8),
OpenGL rounds to what it has and a warning says so once, at opening.

Threads and time limits: all GLFW and OpenGL calls run on one daemon thread (:mod:`._worker`) that also
processes the window's events while idle (so the window manager never marks it "not responding" while an
operator prompt waits); every call is waited for at most the rig file's ``projector.timeout_s``. A missing display
(no ``$DISPLAY`` / ``$WAYLAND_DISPLAY``, or the rig file's ``x_display`` has no X server), a display index beyond the monitors, or a window that fails to open is a
RigError naming the display and the step.
"""

from __future__ import annotations

import logging
import os
import sys
import threading
import time
from typing import Any

import numpy as np

from lftransfer.rig.base import RigError
from lftransfer.rig.hardware._worker import Worker, WorkerStuck, WorkerTimeout
from lftransfer.rig.hardware.config import ProjectorConfig
from lftransfer.rig.x11 import window_image

__all__ = ["ProjectorWindow"]

_log = logging.getLogger(__name__)

# -- the shared window thread ----------------------------------------------------------------------------------

_lock = threading.Lock()
_worker: Worker | None = None
_windows: set["ProjectorWindow"] = set()       # open windows (touched on the window thread only)
_glfw_errors: list[tuple[int, str]] = []       # errors GLFW reported since the last _take_errors()
_glfw: Any = None                               # the glfw module once imported


def _poll_events() -> None:
    if _windows and _glfw is not None:
        _glfw.poll_events()


def _window_thread() -> Worker:
    global _worker
    with _lock:
        if _worker is None:
            _worker = Worker("lft-projector", idle=_poll_events, idle_s=0.05)
        return _worker


def _on_glfw_error(code: int, description: bytes | str) -> None:
    text = description.decode(errors="replace") if isinstance(description, bytes) else str(description)
    _glfw_errors.append((int(code), text))


def _take_errors() -> str:
    text = "; ".join(d for _, d in _glfw_errors)
    _glfw_errors.clear()
    return text


def _import_glfw() -> Any:
    global _glfw
    if _glfw is None:
        try:
            import glfw
        except ImportError as exc:
            raise RigError("the projector window needs the glfw package: pip install lftransfer[hardware] "
                           f"({exc})") from None
        glfw.set_error_callback(_on_glfw_error)
        _glfw = glfw
    return _glfw


def _import_gl() -> Any:
    try:
        from OpenGL import GL
    except ImportError as exc:
        raise RigError(f"the projector window needs PyOpenGL: pip install lftransfer[hardware] ({exc})") from None
    return GL


def _monitor_name(glfw: Any, monitor: Any) -> str:
    name = glfw.get_monitor_name(monitor)
    return name.decode(errors="replace") if isinstance(name, bytes) else str(name)


# -- the window --------------------------------------------------------------------------------------------------

class ProjectorWindow:
    """A borderless full-screen window on monitor ``config.display`` showing images pixel for pixel.

    Args:
        config: the projector's table of the rig file (display, width, height, bits, timeout_s).

    Raises:
        RigError: no display, no such monitor, a monitor that cannot run at width x height, a window or an
            OpenGL context that fails to open, or a step overrunning ``timeout_s``; the message names the display
            and the step.
    """

    def __init__(self, config: ProjectorConfig) -> None:
        self.config = config
        self.label = f"projector (display {config.display})"
        self.monitor_name = "?"
        self.framebuffer_bits = 8
        self._window: Any = None
        self._tex = None
        self._fbo = None
        self._closed = False
        self._x11 = False
        self._worker = _window_thread()
        if config.x_display:
            # GLFW takes the X display from $DISPLAY when it starts: the rig file's display wins over the session's
            if _windows and os.environ.get("DISPLAY") != config.x_display:
                self._closed = True
                raise RigError(f"{self.label}: another projector window is open on DISPLAY="
                               f"{os.environ.get('DISPLAY')!r}; one process drives one X display")
            os.environ["DISPLAY"] = config.x_display
            os.environ.pop("WAYLAND_DISPLAY", None)
            self.label = f"projector (display {config.display} of X display {config.x_display})"
        if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
            self._closed = True
            raise RigError(f"{self.label}: no display to open the projector window on ($DISPLAY and "
                           "$WAYLAND_DISPLAY are not set; start the X server or set DISPLAY, e.g. DISPLAY=:0)")
        try:
            self._call(self._open, step="opening the projector window")
        except BaseException:
            self._closed = True
            raise
        _log.info("%s: window open on %s, %dx%d, %d bits per channel", self.label, self.monitor_name,
                  config.width, config.height, self.framebuffer_bits)

    # -- plumbing ----------------------------------------------------------------------------------------------

    def _call(self, fn: Any, *args: Any, step: str) -> Any:
        try:
            return self._worker.call(fn, *args, timeout=self.config.timeout_s, what=step)
        except WorkerTimeout:
            raise RigError(f"{self.label}: {step} did not finish within {self.config.timeout_s:g} s (the window "
                           "system or the graphics driver does not answer)") from None
        except WorkerStuck as exc:
            raise RigError(f"{self.label}: the window thread is blocked ({exc}); cannot go on with {step}") \
                from None
        except RigError:
            raise
        except Exception as exc:  # noqa: BLE001  (GLFW / OpenGL faults)
            raise RigError(f"{self.label}: {step} failed: {type(exc).__name__}: {exc}") from exc

    # -- on the window thread ----------------------------------------------------------------------------------

    def _fail(self, step: str, what: str) -> RigError:
        errors = _take_errors()
        return RigError(f"{self.label}: {step}: {what}" + (f" ({errors})" if errors else ""))

    def _open(self) -> None:
        glfw = _import_glfw()
        _take_errors()
        if not _windows:
            if not glfw.init():
                raise self._fail("opening the projector window", "the window system cannot be reached from "
                                 f"DISPLAY={os.environ.get('DISPLAY', '')!r}")
        try:
            self._open_window(glfw)
        except BaseException:
            self._destroy(glfw)
            raise

    def _open_window(self, glfw: Any) -> None:
        c = self.config
        step = "opening the projector window"
        monitors = glfw.get_monitors() or []
        if c.display >= len(monitors):
            names = ", ".join(f"{i}: {_monitor_name(glfw, m)}" for i, m in enumerate(monitors)) or "none"
            raise self._fail(step, f"there is no display {c.display}; the window system has {len(monitors)} "
                             f"monitor(s) ({names})")
        monitor = monitors[c.display]
        self.monitor_name = _monitor_name(glfw, monitor)
        mode = glfw.get_video_mode(monitor)
        size = (mode.size.width, mode.size.height)
        refresh = mode.refresh_rate
        region = c.x is not None
        if region and (size[0] < c.x + c.width or size[1] < c.y + c.height):
            raise self._fail(step, f"display {c.display} ({self.monitor_name}) is {size[0]}x{size[1]}: the "
                             f"projector's region {c.width}x{c.height} at ({c.x}, {c.y}) does not fit on it")
        if not region and size != (c.width, c.height):
            modes = [(m.size.width, m.size.height, m.refresh_rate) for m in glfw.get_video_modes(monitor) or []]
            fitting = [m for m in modes if m[:2] == (c.width, c.height)]
            if not fitting:
                raise self._fail(step, f"display {c.display} ({self.monitor_name}) runs at {size[0]}x{size[1]} "
                                 f"and offers no {c.width}x{c.height} mode, the projector's size in the rig file")
            refresh = max(m[2] for m in fitting)
            _log.warning("%s: display %s runs at %dx%d; switching it to %dx%d @ %d Hz while the window is open",
                         self.label, self.monitor_name, *size, c.width, c.height, refresh)
        bits = c.bits if c.bits > 8 else mode.bits.red
        glfw.default_window_hints()
        for hint, value in ((glfw.RED_BITS, bits), (glfw.GREEN_BITS, bits), (glfw.BLUE_BITS, bits),
                            (glfw.REFRESH_RATE, refresh), (glfw.DECORATED, False), (glfw.RESIZABLE, False),
                            (glfw.AUTO_ICONIFY, False), (glfw.FOCUS_ON_SHOW, False), (glfw.FLOATING, True),
                            (glfw.CENTER_CURSOR, False), (glfw.DOUBLEBUFFER, True), (glfw.SAMPLES, 0),
                            (glfw.SRGB_CAPABLE, False), (glfw.SCALE_TO_MONITOR, False),
                            (glfw.VISIBLE, not region)):
            glfw.window_hint(hint, value)
        # the whole monitor: full screen; a region of it: a borderless window placed there
        window = glfw.create_window(c.width, c.height, "lftransfer projector", None if region else monitor, None)
        if not window:
            raise self._fail(step, "the window system refused to open a full-screen window" if not region else
                             "the window system refused to open the projector's window")
        if region:
            mx, my = glfw.get_monitor_pos(monitor)
            glfw.set_window_pos(window, mx + c.x, my + c.y)
            glfw.show_window(window)
        self._window = window
        _windows.add(self)
        glfw.make_context_current(window)
        glfw.swap_interval(1)
        glfw.set_input_mode(window, glfw.CURSOR, glfw.CURSOR_HIDDEN)
        fb = tuple(glfw.get_framebuffer_size(window))
        if fb != (c.width, c.height):
            raise self._fail(step, f"the window's framebuffer is {fb[0]}x{fb[1]}, not {c.width}x{c.height} "
                             "(display scaling on? the image would not be pixel-exact)")
        try:
            self._x11 = glfw.get_platform() == glfw.PLATFORM_X11
        except Exception:  # noqa: BLE001  (GLFW < 3.4)
            self._x11 = bool(os.environ.get("DISPLAY")) and os.environ.get("XDG_SESSION_TYPE") != "wayland"
        self._identity_gamma(glfw, monitor)
        self._init_gl()
        self._present(np.zeros((c.height, c.width, 3), np.uint8 if c.bits <= 8 else np.uint16))

    def _identity_gamma(self, glfw: Any, monitor: Any) -> None:
        try:
            ramp = glfw.get_gamma_ramp(monitor)
            if ramp is None:
                return
            red = np.asarray(ramp.red, np.float64)
            if red.size < 2:
                return
            ident = np.linspace(0.0, 1.0, red.size)
            # identity at the ramp's own resolution (X servers often store i << 8 rather than i * 65535 / 255)
            if max(np.abs(np.asarray(ch, np.float64) - ident).max() for ch in (ramp.red, ramp.green, ramp.blue)) \
                    > 0.5 / (red.size - 1):
                glfw.set_gamma(monitor, 1.0)
                _log.warning("%s: display %s had a non-identity gamma ramp (night light, calibration profile?); "
                             "set to the identity while the projector window is open", self.label,
                             self.monitor_name)
        except Exception:  # noqa: BLE001  (servers without gamma ramps: nothing to undo)
            _log.debug("%s: no gamma ramp access", self.label, exc_info=True)
        _take_errors()

    def _init_gl(self) -> None:
        GL = _import_gl()
        c = self.config
        version = GL.glGetString(GL.GL_VERSION) or b"0.0"
        major = int(version.split(b".")[0].split(b" ")[-1] or 0)
        if major < 3:
            raise RigError(f"{self.label}: opening the projector window: OpenGL {version.decode()} is too old "
                           "(3.0 needed for glBlitFramebuffer)")
        for cap in (GL.GL_DITHER, GL.GL_BLEND, GL.GL_SCISSOR_TEST, GL.GL_FRAMEBUFFER_SRGB, GL.GL_MULTISAMPLE):
            GL.glDisable(cap)
        self.framebuffer_bits = int(GL.glGetFramebufferAttachmentParameteriv(
            GL.GL_FRAMEBUFFER, GL.GL_BACK_LEFT, GL.GL_FRAMEBUFFER_ATTACHMENT_RED_SIZE))
        if c.bits > self.framebuffer_bits:
            _log.warning("%s: the display gives %d bits per channel; the projector's %d-bit codes are rounded to "
                         "%d bits", self.label, self.framebuffer_bits, c.bits, self.framebuffer_bits)
        self._tex = GL.glGenTextures(1)
        GL.glBindTexture(GL.GL_TEXTURE_2D, self._tex)
        GL.glTexParameteri(GL.GL_TEXTURE_2D, GL.GL_TEXTURE_MIN_FILTER, GL.GL_NEAREST)
        GL.glTexParameteri(GL.GL_TEXTURE_2D, GL.GL_TEXTURE_MAG_FILTER, GL.GL_NEAREST)
        GL.glTexParameteri(GL.GL_TEXTURE_2D, GL.GL_TEXTURE_MAX_LEVEL, 0)
        internal, kind = (GL.GL_RGB8, GL.GL_UNSIGNED_BYTE) if c.bits <= 8 else (GL.GL_RGB16, GL.GL_UNSIGNED_SHORT)
        GL.glTexImage2D(GL.GL_TEXTURE_2D, 0, internal, c.width, c.height, 0, GL.GL_RGB, kind, None)
        self._fbo = GL.glGenFramebuffers(1)
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, self._fbo)
        GL.glFramebufferTexture2D(GL.GL_READ_FRAMEBUFFER, GL.GL_COLOR_ATTACHMENT0, GL.GL_TEXTURE_2D, self._tex, 0)
        if GL.glCheckFramebufferStatus(GL.GL_READ_FRAMEBUFFER) != GL.GL_FRAMEBUFFER_COMPLETE:
            raise RigError(f"{self.label}: opening the projector window: the image framebuffer is incomplete")
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, 0)

    def _present(self, image: np.ndarray) -> float:
        glfw = _glfw
        GL = _import_gl()
        c = self.config
        glfw.make_context_current(self._window)
        glfw.poll_events()
        if c.bits <= 8:
            data, kind = np.ascontiguousarray(image, np.uint8), GL.GL_UNSIGNED_BYTE
        else:
            scale = 65535.0 / ((1 << c.bits) - 1)
            data = np.round(np.minimum(image, (1 << c.bits) - 1).astype(np.float32) * scale).astype(np.uint16)
            data, kind = np.ascontiguousarray(data), GL.GL_UNSIGNED_SHORT
        GL.glBindTexture(GL.GL_TEXTURE_2D, self._tex)
        GL.glPixelStorei(GL.GL_UNPACK_ALIGNMENT, 1)
        GL.glTexSubImage2D(GL.GL_TEXTURE_2D, 0, 0, 0, c.width, c.height, GL.GL_RGB, kind, data)
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, self._fbo)
        GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, 0)
        GL.glDrawBuffer(GL.GL_BACK)
        # row 0 of the image is the top row: flip while copying (GL's origin is the bottom left)
        GL.glBlitFramebuffer(0, 0, c.width, c.height, 0, c.height, c.width, 0, GL.GL_COLOR_BUFFER_BIT,
                             GL.GL_NEAREST)
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, 0)
        glfw.swap_buffers(self._window)
        GL.glFinish()                     # returns once the swap has been carried out
        return time.monotonic()

    def _read_front(self) -> np.ndarray:
        glfw = _glfw
        c = self.config
        glfw.make_context_current(self._window)
        if self._x11:
            # what the X server shows (Mesa's software rasteriser reads GL_FRONT of a window as zeros)
            values, bits = window_image(glfw.get_x11_display(), glfw.get_x11_window(self._window),
                                         c.width, c.height)
        else:
            GL = _import_gl()
            GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, 0)
            GL.glReadBuffer(GL.GL_FRONT)
            GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 1)
            raw = GL.glReadPixels(0, 0, c.width, c.height, GL.GL_RGB, GL.GL_UNSIGNED_SHORT)
            values = np.frombuffer(raw, np.uint16).reshape(c.height, c.width, 3)[::-1]
            bits = 16
        if bits == c.bits:
            return values.astype(np.uint8 if c.bits <= 8 else np.uint16)
        levels = (1 << c.bits) - 1
        out = np.round(values.astype(np.float64) * (levels / ((1 << bits) - 1)))
        return out.astype(np.uint8 if c.bits <= 8 else np.uint16)

    def _destroy(self, glfw: Any) -> None:
        if self._window is not None:
            try:
                glfw.make_context_current(self._window)
                if self._fbo is not None or self._tex is not None:
                    GL = _import_gl()
                    if self._fbo is not None:
                        GL.glDeleteFramebuffers(1, [self._fbo])
                    if self._tex is not None:
                        GL.glDeleteTextures([self._tex])
            except Exception:  # noqa: BLE001  (the context goes with the window anyway)
                _log.debug("%s: GL clean-up failed", self.label, exc_info=True)
            glfw.make_context_current(None)
            glfw.destroy_window(self._window)
            self._window = None
        _windows.discard(self)
        if not _windows:
            glfw.terminate()          # restores gamma ramps and video modes
        _take_errors()

    # -- public ------------------------------------------------------------------------------------------------

    @property
    def shape(self) -> tuple[int, int, int]:
        """(H, W, 3) of the images it takes."""
        return (self.config.height, self.config.width, 3)

    @property
    def dtype(self) -> type:
        """uint8 for an 8-bit projector, else uint16."""
        return np.uint8 if self.config.bits <= 8 else np.uint16

    def show(self, image: np.ndarray, step: str = "showing an image") -> float:
        """Show ``image`` until the next call, and return once the frame has been presented.

        Args:
            image: (H, W, 3) RGB codes, uint8 for an 8-bit projector, else uint16 codes of ``bits`` bits (values
                above 2^bits - 1 are clipped).
            step: what the caller is doing, for messages.

        Returns:
            ``time.monotonic()`` right after the buffer swap was carried out (``glFinish`` after the swap; with
            vsync on that is at the vertical blank the frame went out at).

        Raises:
            ValueError: wrong shape or dtype.
            RigError: the window is closed, or presenting overran ``timeout_s``.
        """
        image = np.asarray(image)
        if image.shape != self.shape or image.dtype != self.dtype:
            raise ValueError(f"projector image must be {self.shape} {np.dtype(self.dtype).name}, got "
                             f"{image.shape} {image.dtype}")
        if self._closed:
            raise RigError(f"{self.label}: the projector window is closed ({step})")
        return self._call(self._present, image, step=step)

    def screenshot(self) -> np.ndarray:
        """What the window shows now, read back from the display (for tests and latency checks).

        On X11 the window's pixels are read from the X server (``XGetImage``: what is on the screen); elsewhere
        OpenGL's front buffer. Channel values are converted to the projector's codes.

        Returns:
            (H, W, 3) RGB codes, uint8 for an 8-bit projector, else uint16.

        Raises:
            RigError: the window is closed, or reading overran ``timeout_s``.
        """
        if self._closed:
            raise RigError(f"{self.label}: the projector window is closed (screenshot)")
        return self._call(self._read_front, step="reading the window back")

    def close(self) -> None:
        """Close the window (idempotent); GLFW ends with the process's last window."""
        if self._closed:
            return
        self._closed = True
        if _glfw is None:
            return
        try:
            self._worker.call(self._destroy, _glfw, timeout=min(self.config.timeout_s, 5.0),
                              what="closing the projector window")
        except (WorkerTimeout, WorkerStuck):
            _log.warning("%s: the window did not close (window thread blocked); left to the process's exit",
                         self.label)
        except Exception:  # noqa: BLE001
            _log.warning("%s: closing the window failed", self.label, exc_info=True)

    def __enter__(self) -> "ProjectorWindow":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
