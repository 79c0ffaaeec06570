"""Tiny scenes and a nominal calibration file, for tests that run the whole pipeline in seconds."""

from __future__ import annotations

from pathlib import Path

import numpy as np

REAL_BLOCK = """
[[real]]
name = "red block"
shape = "box"
size = [0.08, 0.06, 0.05]
translate = [0.0, -0.005, 0.08]
rotate_deg = [0.0, -30.0, 0.0]
[real.material]
albedo = [0.9, 0.35, 0.25]
"""

SYNTHETIC_CUBE = """
[[synthetic]]
name = "green cube"
shape = "box"
size = [0.06, 0.06, 0.06]
translate = [0.0, 0.0, -0.08]
rotate_deg = [0.0, 30.0, 0.0]
[synthetic.material]
albedo = [0.3, 0.85, 0.35]
"""


def tiny_scene_text(*, light=(0.30, 0.12, 0.0), intensity=(2.0, 2.0, 2.0), real: bool = True,
                    synthetic: bool = True, view=(48, 36), gt_spp: int = 8) -> str:
    """The Fig. 4 objects on a 3 x 4 lenslet rig with tiny devices (a run takes a few seconds)."""
    text = f"""
[rig]
rows = 3
cols = 4
lf_camera = [160, 120]
projector = [80, 60]
angular_samples = 8

[view]
resolution = [{view[0]}, {view[1]}]

[light]
position = [{light[0]}, {light[1]}, {light[2]}]
intensity = [{intensity[0]}, {intensity[1]}, {intensity[2]}]

[render]
gt_spp = {gt_spp}
spp = 2
"""
    return text + (REAL_BLOCK if real else "") + (SYNTHETIC_CUBE if synthetic else "")


def write_tiny_scene(path: Path, **kw) -> Path:
    path = Path(path)
    path.write_text(tiny_scene_text(**kw), encoding="utf-8")
    return path


def nominal_calibration(scene):
    """A :class:`Calibration` holding the rig file's own values (as if calibration had measured them exactly)."""
    from lftransfer.calibration.pose import ArrayPose
    from lftransfer.calibration.radiometric import Radiometry, VignettingPolynomial
    from lftransfer.calibration.rig import Calibration
    from lftransfer.rig.model import nominal_rig

    r = scene.rig
    radiometry = Radiometry(camera_gamma=r.camera_gamma, camera_exposure=r.exposure,
                            vignetting_poly=VignettingPolynomial(degree=0, coeffs=(1.0,),
                                                                 shape=(r.lf_camera[1], r.lf_camera[0])),
                            projector_gamma=r.projector_gamma, cross_talk=np.eye(3), black_level=np.zeros(3),
                            max_radiance=r.projector_max_radiance)
    model = radiometry.apply(nominal_rig(r))
    pose = ArrayPose(tilt=(0.0, 0.0), rotation=0.0, offset=(0.0, 0.0), scale=1.0)
    return Calibration(model=model, lattice=None, distortion=None, projector_fit=None, radiometry=radiometry,
                       pose=pose)
