"""The rig's cameras: OpenCV ``VideoCapture`` sources and GenICam cameras (``harvesters``).

Both kinds share :class:`Camera`: :meth:`Camera.grab` drops stale frames, averages fresh ones and returns
(H, W, 3) float32 codes of the rig file's bit depth (RGB order, grey cameras replicated to three channels,
the size checked against the rig file). Every device call runs on the camera's own worker thread
(:mod:`._worker`) and is waited for at most ``timeout_s``: a camera that stops delivering raises
:class:`~lftransfer.rig.base.RigError` naming the device and the step instead of hanging the run. OpenCV's own
time limits are asked for as well, so the worker is seldom left blocked: ``CAP_PROP_OPEN_TIMEOUT_MSEC`` /
``CAP_PROP_READ_TIMEOUT_MSEC`` for files and streams (FFmpeg), and for live cameras the V4L2 backend's
``select()`` wait, ``OPENCV_VIDEOIO_V4L_SELECT_TIMEOUT`` (set to ``timeout_s`` rounded up unless the environment
sets it; OpenCV reads it once per process).

Sources (:attr:`CameraConfig.source`): a device index or a V4L2 path (live cameras), a video file or an
image-sequence pattern (recordings, for tests and replays: the end of the recording is an error at once, with no
wait), or ``genicam:SERIAL``; stream URLs are read by :class:`~lftransfer.rig.hardware.stream.StreamCamera`;
:func:`~lftransfer.rig.hardware.cameras.open_camera` opens the kind a rig file names.

Code conversion (:attr:`CameraConfig.bits`): uint8 frames are scaled to full scale of ``bits``; uint16 frames
hold ``bits``-bit codes in the low bits (or, with ``msb_aligned``, the high bits); float frames are taken as
codes. Averaging is done on float codes; rounding to integers is the caller's (``HardwareRig.capture_lf``).
"""

from __future__ import annotations

import logging
import math
import os
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from lftransfer.rig.base import RigError
from lftransfer.rig.hardware._worker import Worker, WorkerStuck, WorkerTimeout
from lftransfer.rig.hardware.config import CameraConfig

__all__ = ["Camera", "GenICamCamera", "OpenCVCamera"]

_log = logging.getLogger(__name__)

_RATIO_TOL = 0.02        # a driver's read-back exposure may differ this much (relative) from what was set


class Camera:
    """What the rig needs of a camera; subclasses provide the device calls (``_open``, ``_read``, ...).

    Args:
        config: the camera's table of the rig file.
        role: how messages name it ("LF camera", "view camera").
    """

    def __init__(self, config: CameraConfig, role: str = "camera") -> None:
        self.config = config
        self.role = role
        self.label = f"{role} ({config.source})"
        self._worker = Worker(f"lft-{role.replace(' ', '-')}")
        self._frames_read = 0
        self._closed = False
        self._scale_warned = False
        self._base_exposure: float | None = None
        self._exposure_scale = 1.0

    # -- device calls, run on the worker thread (subclasses) ---------------------------------------------------

    def _open(self) -> None:
        raise NotImplementedError

    def _read(self) -> np.ndarray | None:
        """One raw frame, or None where the device had none (a recording that ended, a failed read)."""
        raise NotImplementedError

    def _get_exposure(self) -> float | None:
        return None

    def _set_exposure(self, value: float) -> float | None:
        """Set the exposure; the value read back, or None where the device refused."""
        return None

    def _release(self) -> None:
        raise NotImplementedError

    # -- helpers -----------------------------------------------------------------------------------------------

    def _call(self, fn: Callable[..., Any], *args: Any, step: str, doing: str, timeout: float | None = None) -> Any:
        """Run a device call on the worker, mapping time-outs and faults to RigError."""
        timeout = self.config.timeout_s if timeout is None else timeout
        try:
            return self._worker.call(fn, *args, timeout=timeout, what=doing)
        except WorkerTimeout:
            raise RigError(f"{self.label}: no answer within {timeout:.3g} s while {doing} ({step}); is the "
                           "camera connected and delivering frames?") from None
        except WorkerStuck as exc:
            raise RigError(f"{self.label}: the camera stopped responding earlier ({exc}); cannot go on with "
                           f"{step}: reconnect the camera and reopen the rig") from None
        except RigError:
            raise
        except Exception as exc:  # noqa: BLE001  (device library faults)
            raise RigError(f"{self.label}: {doing} failed ({step}): {type(exc).__name__}: {exc}") from exc

    def _check_open(self, step: str) -> None:
        if self._closed:
            raise RigError(f"{self.label}: the camera is closed ({step})")

    def to_codes(self, frame: np.ndarray) -> np.ndarray:
        """A raw frame as (H, W, 3) float32 codes of ``config.bits`` bits, RGB.

        Args:
            frame: (H, W), (H, W, 1), (H, W, 3) RGB or (H, W, 4) RGBA frame, uint8, uint16 or float.

        Returns:
            (H, W, 3) float32 codes.

        Raises:
            RigError: the size differs from the rig file's, or the frame has an unusable layout.
        """
        c = self.config
        a = np.asarray(frame)
        if a.ndim == 3 and a.shape[2] == 1:
            a = a[..., 0]
        if c.planar:
            if a.ndim != 2 or a.shape[0] % 3:
                raise RigError(f"{self.label}: frame of shape {a.shape}; a planar camera (planar = true) delivers "
                               "(3 H, W) monochrome frames")
            a = np.moveaxis(a.reshape(3, a.shape[0] // 3, a.shape[1]), 0, -1)
        elif a.ndim == 2:
            a = np.repeat(a[..., None], 3, axis=2)
        elif a.ndim == 3 and a.shape[2] == 4:
            a = a[..., :3]
        if a.ndim != 3 or a.shape[2] != 3:
            raise RigError(f"{self.label}: frame of shape {a.shape}; expected (H, W), (H, W, 1), (H, W, 3) or "
                           "(H, W, 4)")
        if a.shape[:2] != (c.height, c.width):
            raise RigError(f"{self.label}: the camera delivers {a.shape[1]}x{a.shape[0]} frames, the rig file "
                           f"says {c.width}x{c.height} (lf_camera/view_camera width and height)")
        if a.dtype == np.uint8:
            out = a.astype(np.float32)
            if c.bits != 8:
                if not self._scale_warned:
                    _log.info("%s: 8-bit frames scaled to %d-bit codes", self.label, c.bits)
                    self._scale_warned = True
                out *= np.float32(c.levels / 255.0)
            return out
        if a.dtype == np.uint16:
            if c.msb_aligned and c.bits < 16:
                a = a >> (16 - c.bits)
            return np.minimum(a, c.levels).astype(np.float32)
        if np.issubdtype(a.dtype, np.integer):
            return np.clip(a, 0, c.levels).astype(np.float32)
        return np.asarray(a, np.float32)

    # -- public ------------------------------------------------------------------------------------------------

    def open(self) -> "Camera":
        """Open the device (within ``timeout_s``) and set its exposure and gain where the rig file gives them.

        Returns:
            self.

        Raises:
            RigError: the source cannot be opened (named), or opening overran ``timeout_s``.
        """
        self._call(self._open, step="opening the camera", doing="opening the device")
        _log.info("%s: open", self.label)
        return self

    def read_frame(self, step: str = "reading a frame") -> tuple[np.ndarray, float]:
        """One fresh frame.

        Args:
            step: what the caller is doing, for messages ("capture_lf after projecting").

        Returns:
            ((H, W, 3) float32 codes, monotonic time the frame arrived).

        Raises:
            RigError: no frame within ``timeout_s`` (a recording's end is an error at once), or a wrong size.
        """
        self._check_open(step)
        c = self.config
        deadline = time.monotonic() + c.timeout_s
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise RigError(f"{self.label}: no frame within {c.timeout_s:g} s during {step}; the camera "
                               "stopped delivering frames (unplugged, or another program holds it?)")
            frame = self._call(self._read, step=step, doing=f"reading frame {self._frames_read + 1}",
                               timeout=left)
            now = time.monotonic()
            if frame is not None:
                self._frames_read += 1
                return self.to_codes(frame), now
            if not c.live:
                raise RigError(f"{self.label}: the recording ended after {self._frames_read} frames during "
                               f"{step}")
            time.sleep(min(0.01, max(0.0, deadline - time.monotonic())))

    def grab(self, frames: int = 1, drop: int = 0, step: str = "grab",
             transform: Callable[[np.ndarray], np.ndarray] | None = None) -> np.ndarray:
        """Drop stale frames, then average fresh ones.

        Args:
            frames: frames averaged, >= 1.
            drop: frames read and thrown away first (stale ones the driver buffered), >= 0.
            step: what the caller is doing, for messages.
            transform: applied to each frame's (H, W, 3) float32 codes before averaging (e.g. a
                linearisation), or None.

        Returns:
            (H, W, 3) float32: the mean of the ``frames`` codes (or transformed frames).

        Raises:
            RigError: a frame did not come within ``timeout_s``, or has the wrong size.
        """
        if frames < 1 or drop < 0:
            raise ValueError(f"grab needs frames >= 1 and drop >= 0, got frames={frames}, drop={drop}")
        for _ in range(drop):
            self.read_frame(step)
        acc: np.ndarray | None = None
        for _ in range(frames):
            f, _t = self.read_frame(step)
            if transform is not None:
                f = np.asarray(transform(f), np.float32)
            acc = f.astype(np.float64) if acc is None else acc + f
        assert acc is not None
        return (acc / frames).astype(np.float32)

    @property
    def exposure_scale(self) -> float:
        """The exposure relative to the rig file's (or the camera's own at opening)."""
        return self._exposure_scale

    continuous = False
    """Whether a reader thread takes every frame as it arrives (:class:`StreamCamera`): then a capture selects frames
    by their arrival time (:meth:`mark_change`) instead of sleeping and dropping."""

    def mark_change(self, not_before: float) -> None:
        """Frames that arrive before ``not_before`` (monotonic seconds) are stale: never returned again (a camera
        read continuously; for the others the caller sleeps and drops frames)."""

    def set_exposure_scale(self, scale: float, step: str = "exposure bracketing") -> bool:
        """Set the exposure to ``scale`` times the base one (the rig file's ``exposure``, else the camera's own).

        Args:
            scale: relative exposure, > 0.
            step: what the caller is doing, for messages.

        Returns:
            Whether the exposure changed (frames taken before are stale then).

        Raises:
            RigError: the camera does not let its exposure be set (exposure bracketing is not supported by it).
        """
        self._check_open(step)
        if abs(scale - self._exposure_scale) <= 1e-9 * scale:
            return False
        base = self._base_exposure
        if base is None or not base > 0:
            raise RigError(f"{self.label}: exposure bracketing (exposure_scale {scale:g}) is not supported by "
                           f"this camera: it reports no exposure to scale ({step})")
        target = base * scale
        got = self._call(self._set_exposure, target, step=step, doing=f"setting the exposure to {target:g}")
        if got is None or abs(got - target) > _RATIO_TOL * target:
            raise RigError(f"{self.label}: exposure bracketing (exposure_scale {scale:g}) is not supported by "
                           f"this camera: the driver refused exposure {target:g}"
                           + ("" if got is None else f" (reads back {got:g})") + f" ({step})")
        self._exposure_scale = scale
        return True

    def close(self) -> None:
        """Release the device (idempotent; a camera stuck in a call is left to its daemon thread)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._worker.call(self._release, timeout=min(self.config.timeout_s, 5.0), what="releasing the device")
        except (WorkerTimeout, WorkerStuck):
            _log.warning("%s: not released (the device does not answer); left to the process's exit", self.label)
        except Exception:  # noqa: BLE001
            _log.warning("%s: releasing failed", self.label, exc_info=True)
        self._worker.stop()

    def __enter__(self) -> "Camera":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# -- OpenCV ----------------------------------------------------------------------------------------------------

class OpenCVCamera(Camera):
    """A camera, video file or image sequence read through ``cv2.VideoCapture``.

    Args:
        config: the camera's table of the rig file (any source but ``genicam:``).
        role: how messages name it ("LF camera").
        capture_factory: ``(source, api_preference, params) -> capture`` making the capture object (an object
            with ``isOpened``, ``read``, ``set``, ``get``, ``release`` like ``cv2.VideoCapture``); None for
            ``cv2.VideoCapture``. Tests pass fakes here.
    """

    def __init__(self, config: CameraConfig, role: str = "camera",
                 capture_factory: Callable[[int | str, int, list[int]], Any] | None = None) -> None:
        if config.kind == "genicam":
            raise ValueError(f"{role} ({config.source}): a genicam: source needs GenICamCamera")
        super().__init__(config, role)
        self._factory = capture_factory
        self._cap: Any = None

    def _open(self) -> None:
        import cv2

        c = self.config
        ms = int(round(c.timeout_s * 1000))
        params: list[int] = []
        if c.live:
            # OpenCV's V4L2 backend waits this long (default 10 s) in select() for a frame; it ignores
            # CAP_PROP_READ_TIMEOUT_MSEC and reads the variable once, at its first capture (a caller's own
            # setting wins)
            os.environ.setdefault("OPENCV_VIDEOIO_V4L_SELECT_TIMEOUT", str(max(1, math.ceil(c.timeout_s))))
        if c.kind == "index":
            api, source = cv2.CAP_ANY, c.source
        elif c.kind == "v4l2":
            api, source = cv2.CAP_V4L2, c.source
        elif c.kind == "images":
            api, source = cv2.CAP_IMAGES, c.source
        else:
            if not Path(str(c.source)).is_file():
                raise RigError(f"{self.label}: cannot open the camera: no such video file")
            api, source = cv2.CAP_ANY, c.source
            params = [cv2.CAP_PROP_OPEN_TIMEOUT_MSEC, ms, cv2.CAP_PROP_READ_TIMEOUT_MSEC, ms]
        if self._factory is not None:
            cap = self._factory(source, api, params)
        else:
            cap = cv2.VideoCapture(source, api, params) if params else cv2.VideoCapture(source, api)
        if cap is None or not cap.isOpened():
            if cap is not None:
                cap.release()
            what = {"index": "no camera at this device index", "v4l2": "no such V4L2 device, or it is busy",
                    "images": "no image file matches the pattern",
                    "video": "the file cannot be decoded"}[c.kind]
            raise RigError(f"{self.label}: cannot open the camera: {what}")
        self._cap = cap
        if c.live:
            cap.set(cv2.CAP_PROP_FRAME_WIDTH, c.width)
            cap.set(cv2.CAP_PROP_FRAME_HEIGHT, c.height)
            cap.set(cv2.CAP_PROP_BUFFERSIZE, 1)        # fewer stale frames where the backend allows
        if c.exposure is not None:
            if c.live and not (cap.set(cv2.CAP_PROP_AUTO_EXPOSURE, 1) or cap.set(cv2.CAP_PROP_AUTO_EXPOSURE, 0.25)):
                _log.warning("%s: the driver refused to turn automatic exposure off", self.label)
            got = self._set_exposure(c.exposure)
            if got is None or abs(got - c.exposure) > _RATIO_TOL * c.exposure:
                _log.warning("%s: the driver refused exposure = %g (reads back %s); the camera's own exposure "
                             "stays", self.label, c.exposure, got)
            else:
                self._base_exposure = float(c.exposure)
        else:
            e = float(cap.get(cv2.CAP_PROP_EXPOSURE))
            self._base_exposure = e if c.live and e > 0 else None
        if c.gain is not None:
            ok = cap.set(cv2.CAP_PROP_GAIN, c.gain)
            got = float(cap.get(cv2.CAP_PROP_GAIN))
            if not ok or abs(got - c.gain) > max(1e-6, _RATIO_TOL * c.gain):
                _log.warning("%s: the driver refused gain = %g (reads back %g)", self.label, c.gain, got)

    def _read(self) -> np.ndarray | None:
        import cv2

        ok, frame = self._cap.read()
        if not ok or frame is None:
            return None
        if frame.ndim == 3 and frame.shape[2] == 3:
            return cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)
        if frame.ndim == 3 and frame.shape[2] == 4:
            return cv2.cvtColor(frame, cv2.COLOR_BGRA2RGB)
        return frame

    def _get_exposure(self) -> float | None:
        import cv2

        return float(self._cap.get(cv2.CAP_PROP_EXPOSURE))

    def _set_exposure(self, value: float) -> float | None:
        import cv2

        if not self._cap.set(cv2.CAP_PROP_EXPOSURE, float(value)):
            return None
        return float(self._cap.get(cv2.CAP_PROP_EXPOSURE))

    def _release(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None


# -- GenICam ---------------------------------------------------------------------------------------------------

_BAYER = {"BayerRG": "RGGB", "BayerBG": "BGGR", "BayerGR": "GRBG", "BayerGB": "GBRG"}


def _import_harvesters():
    try:
        from harvesters.core import Harvester
    except ImportError as exc:
        raise RigError("GenICam cameras need the harvesters package: pip install lftransfer[genicam] "
                       f"({exc})") from None
    return Harvester


class GenICamCamera(Camera):
    """A GenICam (GigE Vision / USB3 Vision) camera through ``harvesters`` (the ``genicam`` extra).

    Mono, RGB/BGR and Bayer pixel formats of 8 to 16 bits are handled (Bayer is demosaiced by OpenCV); the
    rig file's ``exposure`` sets ``ExposureTime`` (microseconds, automatic exposure off) and ``gain`` sets
    ``Gain`` where the camera has those nodes.

    Args:
        config: the camera's table of the rig file (a ``genicam:SERIAL`` source with ``cti``).
        role: how messages name it.
    """

    def __init__(self, config: CameraConfig, role: str = "camera") -> None:
        if config.kind != "genicam":
            raise ValueError(f"{role} ({config.source}): GenICamCamera needs a genicam:SERIAL source")
        super().__init__(config, role)
        self._harvester: Any = None
        self._ia: Any = None

    def _node(self, name: str) -> Any:
        try:
            return getattr(self._ia.remote_device.node_map, name)
        except Exception:  # noqa: BLE001  (absent node)
            return None

    def _open(self) -> None:
        Harvester = _import_harvesters()
        c = self.config
        if c.cti is None or not c.cti.is_file():
            raise RigError(f"{self.label}: cannot open the camera: the GenTL producer {c.cti} does not exist")
        h = Harvester()
        self._harvester = h
        h.add_file(str(c.cti))
        h.update()
        serials = [str(getattr(d, "serial_number", "")) for d in h.device_info_list]
        if c.serial not in serials:
            raise RigError(f"{self.label}: cannot open the camera: no camera with serial number {c.serial} "
                           f"(found: {', '.join(serials) or 'none'})")
        key = {"serial_number": c.serial}
        self._ia = h.create(key) if hasattr(h, "create") else h.create_image_acquirer(**key)
        if c.exposure is not None:
            auto = self._node("ExposureAuto")
            if auto is not None:
                try:
                    auto.value = "Off"
                except Exception:  # noqa: BLE001
                    _log.warning("%s: the camera refused ExposureAuto = Off", self.label)
            got = self._set_exposure(c.exposure)
            if got is None or abs(got - c.exposure) > _RATIO_TOL * c.exposure:
                _log.warning("%s: the camera refused ExposureTime = %g (reads back %s)", self.label,
                             c.exposure, got)
            else:
                self._base_exposure = float(c.exposure)
        else:
            self._base_exposure = self._get_exposure()
        if c.gain is not None:
            node = self._node("Gain")
            try:
                node.value = float(c.gain)
            except Exception:  # noqa: BLE001
                _log.warning("%s: the camera refused Gain = %g", self.label, c.gain)
        self._ia.start()

    def _read(self) -> np.ndarray | None:
        import cv2

        with self._ia.fetch(timeout=self.config.timeout_s) as buffer:
            comp = buffer.payload.components[0]
            fmt = str(getattr(comp, "data_format", "Mono8"))
            h, w = int(comp.height), int(comp.width)
            data = np.asarray(comp.data)
            frame = data.reshape(h, w, -1).copy() if data.size != h * w else data.reshape(h, w).copy()
        if frame.ndim == 3 and frame.shape[2] == 1:
            frame = frame[..., 0]
        for prefix, pattern in _BAYER.items():
            if fmt.startswith(prefix):
                return cv2.cvtColor(frame, getattr(cv2, f"COLOR_Bayer{pattern}2RGB"))
        if fmt.startswith("BGR") and frame.ndim == 3:
            return frame[..., ::-1]
        return frame

    def _get_exposure(self) -> float | None:
        node = self._node("ExposureTime")
        try:
            return float(node.value) if node is not None else None
        except Exception:  # noqa: BLE001
            return None

    def _set_exposure(self, value: float) -> float | None:
        node = self._node("ExposureTime")
        if node is None:
            return None
        try:
            node.value = float(value)
            return float(node.value)
        except Exception:  # noqa: BLE001
            return None

    def _release(self) -> None:
        if self._ia is not None:
            try:
                self._ia.stop()
            finally:
                self._ia.destroy()
                self._ia = None
        if self._harvester is not None:
            self._harvester.reset()
            self._harvester = None
