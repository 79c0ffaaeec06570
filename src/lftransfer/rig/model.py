"""What is known about a rig's optics and devices: the lens array, the LF camera and the projector models.

The pipeline builds these from the rig file (nominal values) or, later, from a calibration; the simulated rig
holds its own, hidden, true copy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lftransfer.lightfield import CameraModel, LightFieldDecoder, LightFieldEncoder, ProjectorModel, ResponseCurve
from lftransfer.optics import LensArray, LensletDevice
from lftransfer.optics.geometry import rotation_xy


@dataclass(frozen=True)
class RigModel:
    """Lens array plus the two devices behind it.

    Attributes:
        array: the lens array (lattice, pitch, focal length, pose in the interface plane).
        camera: LF camera model (pixel geometry, bit depth, response, exposure).
        projector: projector model (pixel geometry, bit depth, response, radiance of a full-code pixel).
        tilt: (about x, about y) radians: the array plane turned out of the world's z = 0 plane about the world
            origin (x first, then y). Renderers work in the array's own frame (:meth:`world_to_array`).
    """

    array: LensArray
    camera: CameraModel
    projector: ProjectorModel
    tilt: tuple[float, float] = (0.0, 0.0)

    def world_to_array(self) -> np.ndarray:
        """(4, 4) rigid transform: world point -> the array's frame (interface plane z = 0)."""
        m = np.eye(4)
        m[:3, :3] = rotation_xy(self.tilt).T
        return m

    def decoder(self, U: int, V: int) -> LightFieldDecoder:
        """Raw LF camera image -> light field on a (V, U) angular grid."""
        return LightFieldDecoder(self.array, self.camera, U, V)

    def encoder(self, U: int, V: int, *, above_black: bool = False) -> LightFieldEncoder:
        """Light field on a (V, U) angular grid -> projector image (``above_black``: the light field is light
        added to what the projector shows at code 0, :class:`~lftransfer.lightfield.LightFieldEncoder`)."""
        return LightFieldEncoder(self.array, self.projector, U, V, above_black=above_black)


def nominal_rig(rig) -> RigModel:
    """The rig model that the rig file describes (``lftransfer.scenes.RigConfig``), devices fronto-parallel."""
    array = LensArray(lattice=rig.lattice, rows=rig.rows, cols=rig.cols, pitch=rig.pitch,
                      focal_length=rig.focal_length, aperture=rig.aperture)
    cam_w, cam_h = rig.lf_camera
    prj_w, prj_h = rig.projector
    camera = CameraModel(device=LensletDevice.fronto_parallel(array, cam_w, cam_h), bits=rig.lf_camera_bits,
                         response=ResponseCurve(tuple(rig.camera_gamma)), exposure=rig.exposure)
    projector = ProjectorModel(device=LensletDevice.fronto_parallel(array, prj_w, prj_h), bits=rig.projector_bits,
                               response=ResponseCurve(tuple(rig.projector_gamma)),
                               max_radiance=rig.projector_max_radiance)
    return RigModel(array=array, camera=camera, projector=projector)
