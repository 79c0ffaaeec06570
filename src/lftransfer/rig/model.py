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
        tilt: (about x, about y) radians: the array plane turned out of its interface's z = 0 plane about the
            interface's origin (x first, then y). Renderers work in the array's own frame (:meth:`world_to_array`).
        placement: where the interface stands in the world, a (4, 4) interface -> world transform as nested
            tuples (a scene's ``[[interface]]`` pose, :meth:`lftransfer.scenes.InterfaceConfig.to_world`); ``()``:
            the world's own frame (one interface, or the first of several).
    """

    array: LensArray
    camera: CameraModel
    projector: ProjectorModel
    tilt: tuple[float, float] = (0.0, 0.0)
    placement: tuple = ()

    def world_to_array(self) -> np.ndarray:
        """(4, 4) rigid transform: world point -> the array's frame (interface plane z = 0)."""
        m = np.eye(4)
        m[:3, :3] = rotation_xy(self.tilt).T
        if self.placement:
            m = m @ np.linalg.inv(np.asarray(self.placement, np.float64))
        return m

    def decoder(self, U: int, V: int) -> LightFieldDecoder:
        """Raw LF camera image -> light field on a (V, U) angular grid."""
        return LightFieldDecoder(self.array, self.camera, U, V)

    def encoder(self, U: int, V: int, *, above_black: bool = False) -> LightFieldEncoder:
        """Light field on a (V, U) angular grid -> projector image (``above_black``: the light field is light
        added to what the projector shows at code 0, :class:`~lftransfer.lightfield.LightFieldEncoder`)."""
        return LightFieldEncoder(self.array, self.projector, U, V, above_black=above_black)


def placed(matrix: np.ndarray | None) -> tuple:
    """A (4, 4) interface -> world transform as :attr:`RigModel.placement` holds it (``()`` for None or the
    identity)."""
    if matrix is None or np.allclose(matrix, np.eye(4), rtol=0, atol=1e-15):
        return ()
    return tuple(tuple(float(x) for x in row) for row in np.asarray(matrix, np.float64))


def nominal_rig(rig, placement: np.ndarray | None = None) -> RigModel:
    """The rig model that the rig file describes (``lftransfer.scenes.RigConfig``), devices fronto-parallel;
    ``placement``: the interface's (4, 4) interface -> world transform (None: the world's frame)."""
    array = LensArray(lattice=rig.lattice, rows=rig.rows, cols=rig.cols, pitch=rig.pitch,
                      focal_length=rig.focal_length, aperture=rig.aperture)
    cam_w, cam_h = rig.lf_camera
    prj_w, prj_h = rig.projector
    camera = CameraModel(device=LensletDevice.fronto_parallel(array, cam_w, cam_h), bits=rig.lf_camera_bits,
                         response=ResponseCurve(tuple(rig.camera_gamma)), exposure=rig.exposure)
    projector = ProjectorModel(device=LensletDevice.fronto_parallel(array, prj_w, prj_h), bits=rig.projector_bits,
                               response=ResponseCurve(tuple(rig.projector_gamma)),
                               max_radiance=rig.projector_max_radiance)
    return RigModel(array=array, camera=camera, projector=projector, placement=placed(placement))


def nominal_interfaces(scene) -> list[RigModel]:
    """The nominal rig model of every light field interface of a scene (its ``[[interface]]`` tables placed in
    the world, each with ``[rig]``'s hardware; ``[rig]`` alone for a scene without them)."""
    if not scene.interfaces:
        return [nominal_rig(scene.rig)]
    return [nominal_rig(i.rig(scene.rig), i.to_world()) for i in scene.interfaces]
