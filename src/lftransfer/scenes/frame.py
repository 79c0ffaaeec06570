"""A scene seen from another rigid frame (e.g. the lens array's own frame when the array is tilted).

Renderers work in the lens array's frame, where the interface is the plane z = 0. When the array is tilted in
the world, everything else (objects, the point light, the view camera) is moved into that frame first.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from lftransfer.optics.geometry import rigid, rotation_xy
from lftransfer.scenes.loader import with_overrides
from lftransfer.scenes.scene import SceneConfig, SyntheticScene

__all__ = ["rotation_xy", "scene_in_frame"]


def scene_in_frame(scene: SceneConfig | SyntheticScene, matrix: np.ndarray) -> SceneConfig | SyntheticScene:
    """The same scene with every position expressed in another frame.

    Args:
        scene: the scene.
        matrix: (4, 4) rigid transform, world point -> point in the new frame.

    Returns:
        A new scene of the same type: objects, point light, the light probe's ball and view camera moved by
        ``matrix``; the rig, the render settings and the environment (a direction field at infinity: its renderers
        take the rotation) unchanged. The identity returns ``scene`` itself. Keyframes move too, exactly at the keys;
        between keys a moved object's Euler angles are interpolated in the new frame, which differs from the
        world frame's interpolation by about the frame's tilt: pose a moving scene first
        (``scene_in_frame(scene.at(t), matrix)``) where that matters.
    """
    m = rigid(matrix)
    if np.allclose(m, np.eye(4), rtol=0, atol=1e-15):
        return scene
    rot, shift = m[:3, :3], m[:3, 3]

    def point(p):
        return (rot @ np.asarray(p, float) + shift).tolist()

    def vector(v):
        return (rot @ np.asarray(v, float)).tolist()

    def turn(rotate_deg):
        return _euler_deg(rot @ Rotation.from_euler("xyz", rotate_deg, degrees=True).as_matrix())

    def move(obj):
        keys = [k.model_copy(update={"translate": None if k.translate is None else point(k.translate),
                                     "rotate_deg": None if k.rotate_deg is None else turn(k.rotate_deg)})
                for k in obj.keyframes]
        return obj.model_copy(update={"translate": point(obj.translate), "rotate_deg": turn(obj.rotate_deg),
                                      "keyframes": keys})

    view = scene.view
    objects = {"real": [move(o) for o in scene.real]} if isinstance(scene, SceneConfig) else {}
    changes = dict(
        **objects,
        synthetic=[move(o) for o in scene.synthetic],
        lights=[lt.model_copy(update={"position": point(lt.position)}) for lt in scene.lights],
        probe=None if scene.probe is None else scene.probe.model_copy(
            update={"ball_centre": point(scene.probe.ball_centre)}),
        view={"origin": point(view.origin), "target": point(view.target), "up": vector(view.up)},
    )
    if not scene.interfaces:
        return with_overrides(scene, **changes)
    # several interfaces: they move with everything else (the first leaves the origin, which a scene file may not
    # do), so the moved scene is a copy of the valid one, not validated again
    def place(interface):
        to_world = m @ interface.to_world()
        return interface.model_copy(update={
            "translate": to_world[:3, 3].tolist(),
            "rotate_deg": _euler_deg(to_world[:3, :3])})

    changes["view"] = view.model_copy(update=changes["view"])
    return scene.model_copy(update={**changes, "interfaces": [place(i) for i in scene.interfaces]})


def _euler_deg(rotation: np.ndarray) -> list[float]:
    """The scene format's ``rotate_deg`` of a (3, 3) rotation. At 90 degrees about y (an interface standing
    sideways) the angles about x and z are not unique: SciPy warns and sets the last to zero, which is the same
    rotation."""
    import warnings

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Gimbal lock detected")
        return Rotation.from_matrix(rotation).as_euler("xyz", degrees=True).tolist()
