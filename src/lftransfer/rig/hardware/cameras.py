"""Opening the camera a rig file names: the kind its source says (:mod:`.camera`'s OpenCV and GenICam cameras,
:mod:`.stream`'s stream URLs), opened and ready to grab."""

from __future__ import annotations

from lftransfer.rig.hardware.camera import Camera, GenICamCamera, OpenCVCamera
from lftransfer.rig.hardware.config import CameraConfig
from lftransfer.rig.hardware.stream import StreamCamera

__all__ = ["open_camera"]


def open_camera(config: CameraConfig, role: str = "camera") -> Camera:
    """Open the camera a rig file's table names.

    Args:
        config: the camera's table.
        role: how messages name it ("LF camera", "view camera").

    Returns:
        An open :class:`GenICamCamera` for ``genicam:`` sources, else an open :class:`OpenCVCamera`.

    Raises:
        RigError: the camera cannot be opened (names the source), or its extra is not installed.
    """
    cam: Camera = GenICamCamera(config, role) if config.kind == "genicam" else \
        StreamCamera(config, role) if config.kind == "stream" else OpenCVCamera(config, role)
    try:
        return cam.open()
    except BaseException:
        cam.close()
        raise
