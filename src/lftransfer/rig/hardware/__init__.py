"""The hardware back-end: a physical rig (projector window, LF camera, view camera) behind the Rig protocol.

- :mod:`.config`: the rig file (TOML, pydantic): :func:`load_rig_file`, :func:`write_rig_value`;
  ``example_rig.toml`` beside this module documents every field.
- :mod:`.camera`: OpenCV (``cv2.VideoCapture``) and GenICam (``harvesters``, the ``genicam`` extra) cameras
  with bounded waits.
- :mod:`.stream`: :class:`~.stream.StreamCamera`, a network stream (URL) read by FFmpeg on a reader thread that
  notes every frame's arrival (re-exported by :mod:`.camera`).
- :mod:`.projector`: the full-screen projector window (GLFW + OpenGL, the ``hardware`` extra).
- :mod:`.rig`: :class:`HardwareRig`, the :class:`~lftransfer.rig.base.Rig` over them.
- :mod:`.latency`: :func:`measure_latency` and :func:`calibrate_latency` (writes ``projector.settle_s``).

Importing this package needs neither a display nor the optional extras: GLFW, OpenGL and harvesters are
imported when a device is opened.
"""

from lftransfer.rig.hardware.config import (CameraConfig, HardwareRigConfig, ProjectorConfig, RigFileError,
                                            ViewCameraConfig, load_rig_file, write_rig_value)
from lftransfer.rig.hardware.latency import LatencyResult, calibrate_latency, measure_latency
from lftransfer.rig.hardware.rig import HardwareRig, no_operator, open_interfaces

__all__ = ["CameraConfig", "HardwareRig", "HardwareRigConfig", "LatencyResult", "ProjectorConfig",
           "RigFileError", "ViewCameraConfig", "calibrate_latency", "load_rig_file", "measure_latency",
           "no_operator", "open_interfaces", "write_rig_value"]
