"""Calibration of several light field interfaces into one world frame (docs/interfaces.md, "Calibration into one
world frame").

Each interface is calibrated from images through its own rig, by every step of
:func:`~lftransfer.calibration.rig.calibrate_rig`, in its own frame (:func:`interface_scene`): the scene's
``[[interface]]`` pose is where the interface was built to stand, and the global pose step measures where its array
really stands against that, from boards the view camera photographs. The view camera's frame is the world's, and
every interface's boards are photographed by it, so the arrays' poses are tied together through it: the first
interface's array is measured in the world like any other. The boards keep clear of the other interfaces' arrays
(:func:`lftransfer.scenes.interfaces.walls`). The point lights are measured once, through the first interface.

The file (:data:`FORMAT`) holds one calibration file's content per interface, each in its interface's frame, with
its name; reading it back places each where the scene's ``[[interface]]`` table says.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np

from lftransfer.calibration.calibration_file import CalibrationFileError
from lftransfer.calibration.rig import (Calibration, calibrate_rig, calibration_from_json, count_calibration_steps,
                                       load_calibration)
from lftransfer.imageio_utils import write_json
from lftransfer.rig.base import Rig
from lftransfer.rig.model import placed
from lftransfer.scenes.frame import scene_in_frame
from lftransfer.scenes.interfaces import interface_names, walls
from lftransfer.validation import read_json

__all__ = ["FORMAT", "InterfacesCalibration", "calibrate_interfaces", "count_steps", "interface_scene",
           "interfaces_from_json", "placed_calibration", "read_calibration"]

FORMAT = "lftransfer-calibration-interfaces/1"


def interface_scene(scene, i: int):
    """The synthetic part of a scene of several interfaces as its ``i``-th interface alone calibrates it: every
    position in that interface's frame (its array in z = 0), its hardware (``[rig]`` with its own lenslet counts),
    no ``[[interface]]`` tables, and the point lights for the first interface only (they are measured once)."""
    face = scene.interfaces[i]
    moved = scene_in_frame(scene, np.linalg.inv(face.to_world()))
    return moved.model_copy(update={"interfaces": [], "rig": face.rig(scene.rig),
                                    "lights": moved.lights if i == 0 else []})


def count_steps(scene) -> int:
    """Progress messages of a scene's calibration (for a progress bar): :func:`calibrate_interfaces`'s for a scene
    of several interfaces, else :func:`~lftransfer.calibration.rig.calibrate_rig`'s."""
    if not scene.interfaces:
        return count_calibration_steps(scene)
    return sum(count_calibration_steps(interface_scene(scene, i)) for i in range(len(scene.interfaces)))


def read_calibration(path, scene):
    """A scene's calibration file: :func:`~lftransfer.calibration.rig.load_calibration` for a scene of one
    interface; for several, the :class:`InterfacesCalibration` (:func:`interfaces_from_json`).

    Raises:
        CalibrationFileError: one line naming the file and the field (a file of one interface for a scene of
            several, and the reverse, included).
    """
    if not scene.interfaces:
        return load_calibration(path, scene)
    path = Path(path)
    return interfaces_from_json(read_json(path, "calibration file", CalibrationFileError), str(path), scene)


@dataclass
class InterfacesCalibration:
    """A calibration of every light field interface of a scene, in one world frame.

    Attributes:
        names: the interfaces' names, in the scene's order.
        interfaces: one :class:`~lftransfer.calibration.rig.Calibration` per interface; each one's ``model``
            carries its interface's placement (the scene's ``[[interface]]`` pose), so its ``world_to_array()``
            takes world points into the array's frame; the first holds the point lights.
    """

    names: tuple[str, ...]
    interfaces: list[Calibration]

    @property
    def model(self):
        """The first interface's rig model (the world's frame)."""
        return self.interfaces[0].model

    @property
    def models(self) -> tuple:
        """Every interface's rig model, in the scene's order."""
        return tuple(c.model for c in self.interfaces)

    @property
    def lights(self) -> list:
        return self.interfaces[0].lights

    @property
    def diagnostics(self) -> dict:
        return self.interfaces[0].diagnostics

    def measures_lights(self, scene) -> bool:
        return self.interfaces[0].measures_lights(scene)

    def light_positions(self, scene) -> list[tuple[float, float, float]]:
        return self.interfaces[0].light_positions(scene)

    def unmeasured_light_note(self, scene, source) -> str | None:
        return self.interfaces[0].unmeasured_light_note(scene, source)

    def to_json(self) -> dict:
        """The calibration as plain JSON data: each interface's calibration file content, in its own frame."""
        return {"format": FORMAT, "interfaces": [{"name": n, "calibration": c.to_json()}
                                                 for n, c in zip(self.names, self.interfaces)]}

    def write(self, path) -> Path:
        """Write the JSON file atomically, as strict JSON."""
        return write_json(path, self.to_json(), indent=1)


def placed_calibration(calibration: Calibration, scene, i: int) -> Calibration:
    """An interface's calibration, made in its frame, placed where the scene's ``[[interface]]`` table says."""
    model = replace(calibration.model, placement=placed(scene.interfaces[i].to_world()))
    return replace(calibration, model=model)


def calibrate_interfaces(rigs: list[Rig], scene, *,
                         progress: Callable[[str], None] | None = None) -> InterfacesCalibration:
    """Calibrate every interface of a scene through its own rig, one after another, into one world frame.

    Args:
        rigs: one rig per interface, in the scene's order (each a whole :class:`~lftransfer.rig.base.Rig`: its LF
            camera, its projector and the shared view camera); the others' projectors stay dark meanwhile.
        scene: the synthetic part of the scene (its ``[[interface]]`` tables, view camera and point lights).
        progress: called with a message per capture or step, each prefixed with the interface's name.

    Returns:
        InterfacesCalibration.
    """
    if len(rigs) != len(scene.interfaces):
        raise ValueError(f"calibrate_interfaces: {len(rigs)} rigs for {len(scene.interfaces)} interfaces")
    out = []
    for i, (rig, name) in enumerate(zip(rigs, interface_names(scene.interfaces))):
        def say(message: str, name=name) -> None:
            if progress is not None:
                progress(f"{name}: {message}")

        made = calibrate_rig(rig, interface_scene(scene, i), progress=say, walls=walls(scene.interfaces, i))
        out.append(placed_calibration(made, scene, i))
    return InterfacesCalibration(names=tuple(interface_names(scene.interfaces)), interfaces=out)


def interfaces_from_json(data, source: str, scene) -> InterfacesCalibration:
    """An :class:`InterfacesCalibration` from a file's JSON value (:meth:`InterfacesCalibration.to_json`).

    Args:
        data: the file's JSON value.
        source: the file's name, for messages.
        scene: the synthetic part of the scene of several interfaces the file must describe.

    Raises:
        CalibrationFileError: not such a file, other interfaces than the scene's (names, in order), or an
            interface's calibration that is invalid or does not fit its hardware; one line naming the field.
    """
    names = interface_names(scene.interfaces)
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        found = data.get("format") if isinstance(data, dict) else None
        raise CalibrationFileError(f"{source}: format: expected {FORMAT!r} (a calibration of {len(names)} light "
                                   f"field interfaces: {', '.join(names)}), found {found!r}; calibrate them with "
                                   f"lft calibrate SCENE")
    if set(data) != {"format", "interfaces"}:
        extra = sorted(set(data) - {"format", "interfaces"})
        raise CalibrationFileError(f"{source}: {extra[0] if extra else 'interfaces'}: expected the keys format and "
                                   f"interfaces only")
    entries = data["interfaces"]
    found = [e.get("name") if isinstance(e, dict) else None for e in entries] if isinstance(entries, list) else None
    if found != names:
        raise CalibrationFileError(f"{source}: interfaces: the file calibrates {found!r}, but the scene's interfaces "
                                   f"are {names!r} (in this order)")
    out = []
    for i, entry in enumerate(entries):
        where = f"{source}: interfaces[{i}]"
        if set(entry) != {"name", "calibration"}:
            raise CalibrationFileError(f"{where}: expected the keys name and calibration")
        made = calibration_from_json(entry["calibration"], f"{where}.calibration", interface_scene(scene, i))
        out.append(placed_calibration(made, scene, i))
    return InterfacesCalibration(names=tuple(names), interfaces=out)
