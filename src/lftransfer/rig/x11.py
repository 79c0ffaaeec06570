"""Reading pixels back from an X server (Xlib through ctypes): what a window, or a region of a screen, shows.

Two users: the projector window checks what it put on the screen (:meth:`ProjectorWindow.screenshot`), and the
device twin (:mod:`lftransfer.sim.twin`) looks at the projector's monitor the way the physical projector does,
by what the window system drew there. Only ``libX11.so.6`` is needed (the window system's own library).
"""

from __future__ import annotations

import ctypes
import threading
from typing import Any

import numpy as np

__all__ = ["XScreen", "window_image"]


class _XImage(ctypes.Structure):
    _fields_ = [("width", ctypes.c_int), ("height", ctypes.c_int), ("xoffset", ctypes.c_int),
                ("format", ctypes.c_int), ("data", ctypes.c_void_p), ("byte_order", ctypes.c_int),
                ("bitmap_unit", ctypes.c_int), ("bitmap_bit_order", ctypes.c_int), ("bitmap_pad", ctypes.c_int),
                ("depth", ctypes.c_int), ("bytes_per_line", ctypes.c_int), ("bits_per_pixel", ctypes.c_int),
                ("red_mask", ctypes.c_ulong), ("green_mask", ctypes.c_ulong), ("blue_mask", ctypes.c_ulong)]


_XErrorHandler = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p)
_x11: Any = None
_x_errors: list[int] = []
_lock = threading.Lock()            # Xlib's error handler is process-wide


@_XErrorHandler
def _on_x_error(display, event):  # noqa: ANN001  (Xlib's callback)
    _x_errors.append(1)
    return 0


def _libx11() -> Any:
    global _x11
    if _x11 is None:
        lib = ctypes.CDLL("libX11.so.6")
        lib.XGetImage.restype = ctypes.POINTER(_XImage)
        lib.XGetImage.argtypes = [ctypes.c_void_p, ctypes.c_ulong, ctypes.c_int, ctypes.c_int, ctypes.c_uint,
                                  ctypes.c_uint, ctypes.c_ulong, ctypes.c_int]
        lib.XDestroyImage.argtypes = [ctypes.POINTER(_XImage)]
        lib.XSync.argtypes = [ctypes.c_void_p, ctypes.c_int]
        lib.XSetErrorHandler.restype = ctypes.c_void_p
        lib.XSetErrorHandler.argtypes = [ctypes.c_void_p]
        lib.XOpenDisplay.restype = ctypes.c_void_p
        lib.XOpenDisplay.argtypes = [ctypes.c_char_p]
        lib.XCloseDisplay.argtypes = [ctypes.c_void_p]
        lib.XDefaultRootWindow.restype = ctypes.c_ulong
        lib.XDefaultRootWindow.argtypes = [ctypes.c_void_p]
        lib.XDisplayWidth.argtypes = [ctypes.c_void_p, ctypes.c_int]
        lib.XDisplayHeight.argtypes = [ctypes.c_void_p, ctypes.c_int]
        lib.XDefaultScreen.argtypes = [ctypes.c_void_p]
        _x11 = lib
    return _x11


def window_image(display: int, window: int, width: int, height: int, x: int = 0,
                 y: int = 0) -> tuple[np.ndarray, int]:
    """The pixels of a window's region as the X server holds them.

    Args:
        display: an open ``Display*`` (as an integer address).
        window: the X window (a screen's root window reads the screen).
        width, height: the region's size, pixels.
        x, y: the region's top-left corner in the window, pixels.

    Returns:
        ((H, W, 3) uint16 channel values, bits per channel).

    Raises:
        RuntimeError: XGetImage failed (window not viewable, region outside it) or an unusual pixel layout.
    """
    lib = _libx11()
    with _lock:
        _x_errors.clear()
        previous = lib.XSetErrorHandler(ctypes.cast(_on_x_error, ctypes.c_void_p))
        try:
            lib.XSync(display, 0)
            image = lib.XGetImage(display, window, x, y, width, height, 0xFFFFFFFF, 2)   # ZPixmap
            lib.XSync(display, 0)
        finally:
            lib.XSetErrorHandler(previous)
        failed = bool(_x_errors)
    if not image or failed:
        raise RuntimeError("XGetImage failed (window not viewable?)")
    try:
        im = image.contents
        if im.bits_per_pixel != 32:
            raise RuntimeError(f"unsupported X image layout: {im.bits_per_pixel} bits per pixel")
        raw = np.ctypeslib.as_array(ctypes.cast(im.data, ctypes.POINTER(ctypes.c_uint8)),
                                    (im.height * im.bytes_per_line,))
        rows = raw.reshape(im.height, im.bytes_per_line)[:, : im.width * 4]
        if (im.byte_order, im.red_mask, im.green_mask, im.blue_mask) == (0, 0xFF0000, 0xFF00, 0xFF):
            return rows.reshape(im.height, im.width, 4)[..., 2::-1].astype(np.uint16), 8   # BGRX bytes
        order = "<u4" if im.byte_order == 0 else ">u4"        # LSBFirst = 0
        pixels = rows.copy().view(order).reshape(im.height, im.width).astype(np.uint32)
        out = np.empty((im.height, im.width, 3), np.uint16)
        bits = 8
        for c, mask in enumerate((im.red_mask, im.green_mask, im.blue_mask)):
            mask = int(mask)
            shift = (mask & -mask).bit_length() - 1
            bits = bin(mask).count("1")
            out[..., c] = ((pixels & mask) >> shift).astype(np.uint16)
        return out, bits
    finally:
        lib.XDestroyImage(image)


class XScreen:
    """A connection to an X display for reading its screen (its default screen's root window).

    Args:
        name: the display, e.g. ``":99"``.

    Raises:
        RuntimeError: the display cannot be opened (no X server there).
    """

    def __init__(self, name: str) -> None:
        lib = _libx11()
        self.name = name
        self._dpy = lib.XOpenDisplay(name.encode())
        if not self._dpy:
            raise RuntimeError(f"cannot open the X display {name!r} (no X server there?)")
        screen = lib.XDefaultScreen(self._dpy)
        self.size = (int(lib.XDisplayWidth(self._dpy, screen)), int(lib.XDisplayHeight(self._dpy, screen)))
        self._root = lib.XDefaultRootWindow(self._dpy)

    def grab(self, width: int, height: int, x: int = 0, y: int = 0) -> np.ndarray:
        """(H, W, 3) uint8 RGB of a region of the screen (8 bits per channel; wider displays are rounded).

        Raises:
            RuntimeError: the region cannot be read (the display went away).
        """
        values, bits = window_image(self._dpy, self._root, width, height, x, y)
        if bits == 8:
            return values.astype(np.uint8)
        return np.round(values * (255.0 / ((1 << bits) - 1))).astype(np.uint8)

    def close(self) -> None:
        """Close the connection (idempotent)."""
        if self._dpy:
            _libx11().XCloseDisplay(self._dpy)
            self._dpy = None
