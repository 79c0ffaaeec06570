"""Small fake rigs for tests: they implement the Rig protocol without rendering."""

from __future__ import annotations

import numpy as np

from lftransfer.rig.requests import LFCapture, LFFrame, RealScene, RigInfo, ViewCapture, ViewFrame


class DarkRig:
    """A rig that sees nothing: every capture is black (a camera pointed at a wall, a lamp off)."""

    def __init__(self, lf_camera=(128, 96), projector=(64, 48), view=(64, 48), bits: int = 12) -> None:
        self.info = RigInfo(lf_camera=tuple(lf_camera), lf_camera_bits=bits, projector=tuple(projector),
                            projector_bits=8, view=tuple(view), kind="fake")
        self.setups = [RealScene()]

    def setup(self, request) -> None:
        self.setups.append(request)

    def project(self, image) -> None:
        self.info.check_projector_image(image)

    def capture_lf(self, request: LFCapture = LFCapture()) -> LFFrame:
        w, h = self.info.lf_camera
        return LFFrame(codes=np.zeros((h, w, 3), np.uint16), bits=self.info.lf_camera_bits,
                       exposure_scale=request.exposure_scale)

    def capture_view(self, request: ViewCapture = ViewCapture()) -> ViewFrame:
        w, h = self.info.view
        return ViewFrame(radiance=np.zeros((h, w, 3), np.float32))

    def close(self) -> None:
        pass
