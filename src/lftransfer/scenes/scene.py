"""Whole scenes: :class:`SceneConfig` (a scene file, real objects included, for the simulated rig and its ground
truth) and :class:`SyntheticScene` (the part the pipeline may know: never the real objects).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pydantic import AliasChoices, Field, ValidationInfo, field_validator, model_validator

from lftransfer.scenes.models import (
    MAX_LIGHTS,
    AnimationConfig,
    EffectConfig,
    MAX_INTERFACES,
    EnvironmentConfig,
    InterfaceConfig,
    LightConfig,
    ProbeConfig,
    RenderConfig,
    RigConfig,
    ViewConfig,
    _Model,
)
from lftransfer.scenes.interfaces import region_problem
from lftransfer.scenes.objects import ObjectConfig, RealObject, SyntheticObject

__all__ = ["SceneConfig", "SyntheticScene", "check_synthetic"]


class _SceneBase(_Model):
    """What every scene has: the rig file's nominal values, the view camera, the point light, the render
    settings and the time line; the subclasses add the objects.

    Attributes:
        rig: light field interface hardware (nominal values; defaults: the paper's rig); every interface's.
        interfaces: several light field interfaces (``[[interface]]``), each ``[rig]``'s hardware at a pose in the
            world (:class:`~lftransfer.scenes.models.InterfaceConfig`); the first stands at the world's origin,
            facing +z. Empty: one interface, ``[rig]``'s, in the world's z = 0.
        view: the view camera.
        lights: the real point lights (their positions as measured by hand): ``[light]`` (one) or
            ``[[light]]`` (several) in the file; empty: the scene is lit by its emitting synthetic objects alone
            (through the projector on the real side).
        probe: the light probe (``[light]`` with ``kind = "probe"``): the environment a mirror ball shows lights
            the synthetic objects, instead of point lights; or None.
        render: render settings.
        animation: the time line of keyframed objects (``[animation]``), or None for a still scene.
        source: the TOML file it was loaded from, or None.
    """

    rig: RigConfig = Field(default_factory=RigConfig)
    interfaces: list[InterfaceConfig] = Field(default_factory=list,
                                              validation_alias=AliasChoices("interface", "interfaces"),
                                              max_length=MAX_INTERFACES)
    view: ViewConfig = Field(default_factory=ViewConfig)
    lights: list[LightConfig] = Field(default_factory=list, validation_alias=AliasChoices("light", "lights"),
                                      max_length=MAX_LIGHTS)
    probe: ProbeConfig | None = None
    render: RenderConfig = Field(default_factory=RenderConfig)
    animation: AnimationConfig | None = None
    source: Path | None = None

    def _sides(self) -> dict[str, list[ObjectConfig]]:
        return {side: getattr(self, side) for side in ("real", "synthetic") if side in type(self).model_fields}

    @property
    def moving(self) -> bool:
        """Whether any object has keyframes."""
        return any(o.moves for objs in self._sides().values() for o in objs)

    def frame_times(self) -> np.ndarray:
        """(F,) float64 frame times of the ``[animation]``, seconds; ``[0.0]`` for a still scene."""
        return self.animation.frame_times() if self.animation is not None else np.zeros(1)

    def at(self, t: float):
        """The scene at time ``t`` (seconds): every keyframed object posed (:meth:`ObjectConfig.at`)."""
        if not self.moving:
            return self
        return self.model_copy(update={side: [o.at(t) for o in objs] for side, objs in self._sides().items()})

    @property
    def emitters(self) -> list[ObjectConfig]:
        """The synthetic objects that emit light."""
        return [o for o in self.synthetic if o.material.type == "emitter"]

    @model_validator(mode="before")
    @classmethod
    def _probe_from_light(cls, data):
        # ``[light] kind = "probe"`` is the light probe, kept apart from the point lights every step measures
        if not isinstance(data, dict):
            return data
        key = "light" if "light" in data else "lights" if "lights" in data else None
        value = data.get(key) if key else None
        entries = [value] if isinstance(value, dict) else value if isinstance(value, list) else []
        probes = [e for e in entries if isinstance(e, dict) and e.get("kind") == "probe"]
        if not probes:
            return data
        if len(entries) > 1:
            raise ValueError("light: a light probe is the scene's only direct light; found it with "
                             f"{len(entries) - 1} other [[light]] table(s)")
        if data.get("probe") is not None:
            raise ValueError("give the light probe once: as [light] kind = 'probe' or as [probe], not both")
        data = {k: v for k, v in data.items() if k != key}
        data["probe"] = probes[0]
        return data

    @field_validator("lights", mode="before")
    @classmethod
    def _one_or_several(cls, value):
        # ``[light]`` is one table, ``[[light]]`` a list of them; None (from older code) is no light
        return [] if value is None else [value] if isinstance(value, (dict, LightConfig)) else value

    @model_validator(mode="after")
    def _something_lights_it(self):
        if not self.lights and not self.emitters and self.probe is None:
            raise ValueError("nothing lights the scene: give a [light] table (the real point light, or kind = "
                             "'probe'), or a synthetic object with material type = 'emitter'")
        return self

    @field_validator("interfaces")
    @classmethod
    def _interfaces_fit(cls, value: list[InterfaceConfig]) -> list[InterfaceConfig]:
        if not value:
            return value
        if len(value) == 1:
            raise ValueError("give two or more [[interface]] tables, or none: one interface is the scene's [rig]")
        if not value[0].at_origin:
            raise ValueError(f"interface[0] ({value[0].name!r}) defines the world frame: give it no translate or "
                             "rotate_deg (it stands at the origin, its real side towards +z)")
        names = [i.name for i in value]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"interface names must differ; {', '.join(map(repr, twice))} is given more than once")
        return value

    @model_validator(mode="after")
    def _animation_fits(self):
        sides = self._sides()
        keyed = [(side, i, o) for side, objs in sides.items() for i, o in enumerate(objs) if o.moves]
        if not keyed:
            return self
        if self.animation is None:
            side, i, o = keyed[0]
            raise ValueError(f"{side}[{i}] ({o.name!r}) has keyframes, but the scene has no [animation] table "
                             "(duration_s, fps)")
        for side, i, o in keyed:
            late = [k.time_s for k in o.keyframes if k.time_s > self.animation.duration_s]
            if late:
                raise ValueError(f"{side}[{i}] ({o.name!r}).keyframes: time_s {late[0]} is after the end of the "
                                 f"animation (duration_s = {self.animation.duration_s})")
            times = np.union1d(self.animation.frame_times(), [k.time_s for k in o.keyframes])
            for t in times:
                posed = o.at(float(t))
                if np.min(posed.scale3) <= 0:
                    raise ValueError(f"{side}[{i}] ({o.name!r}): its interpolated scale is not positive at "
                                     f"t = {t:.4g} s ({posed.scale3.tolist()})")
                problem = region_problem(side, posed, self.interfaces, when=f" at t = {t:.4g} s")
                if problem:
                    raise ValueError(f"{side}[{i}]: {problem}")
        return self


class SyntheticScene(_SceneBase):
    """What the pipeline may know of a scene: the rig file's nominal values, the view camera, the point light as
    measured by hand, the render settings, the time line and the synthetic objects; never the real objects.

    Attributes:
        synthetic: objects of the synthetic half-space (bounding boxes in z < 0; with several interfaces, on the
            synthetic side of at least one).
    """

    synthetic: list[SyntheticObject] = Field(default_factory=list)


class SceneConfig(_SceneBase):
    """A whole scene file, real objects included (for the simulated rig and its ground truth).

    Attributes:
        real: objects of the real half-space (bounding boxes in z > 0; with several interfaces, on the real side
            of all).
        synthetic: objects of the synthetic half-space (bounding boxes in z < 0; with several interfaces, on the
            synthetic side of at least one).
        effect: the effect measured per verified frame (``[effect]``), or None; verification data, like the
            real objects, so the pipeline's part of the scene does not hold it.
        environment: the light of the room around the real objects (``[environment]``), or None (a dark room);
            hidden truth like the real objects: the simulated rig lights them by it, and the pipeline measures
            it through the light probe.
    """

    real: list[RealObject] = Field(default_factory=list)
    synthetic: list[SyntheticObject] = Field(default_factory=list, validate_default=True)
    effect: EffectConfig | None = None
    environment: EnvironmentConfig | None = None

    @field_validator("synthetic")
    @classmethod
    def _some_object(cls, value: list[ObjectConfig], info: ValidationInfo) -> list[ObjectConfig]:
        real = info.data.get("real")
        if real is not None and not real and not value:
            raise ValueError("a scene needs at least one [[real]] or [[synthetic]] object, found none")
        return value

    @model_validator(mode="after")
    def _effect_names_objects(self):
        e = self.effect
        if e is None:
            return self
        real, synthetic = [o.name for o in self.real], [o.name for o in self.synthetic]
        if real.count(e.on) != 1:
            raise ValueError(f"effect.on: expected the name of one [[real]] object ({', '.join(map(repr, real))}), "
                             f"found {e.on!r}" + (" (more than one object has it)" if e.on in real else ""))
        if synthetic.count(e.by) != 1:
            raise ValueError(f"effect.by: expected the name of one [[synthetic]] object "
                             f"({', '.join(map(repr, synthetic))}), found {e.by!r}"
                             + (" (more than one object has it)" if e.by in synthetic else ""))
        if e.kind == "shadow" and not self.lights and len(self.emitters) == 1 and self.emitters[0].name == e.by:
            raise ValueError(f"effect.by: {e.by!r} is the only light of the scene: it cannot shadow anything")
        return self

    def synthetic_part(self) -> SyntheticScene:
        """The part of the scene the pipeline is given (everything but the real objects)."""
        return SyntheticScene.model_construct(**{k: getattr(self, k) for k in SyntheticScene.model_fields})


def check_synthetic(scene) -> SyntheticScene:
    """``scene`` if it is the synthetic part of a scene, else a TypeError: the pipeline never gets real objects."""
    if not isinstance(scene, SyntheticScene):
        raise TypeError(f"the pipeline takes the synthetic part of a scene (SceneConfig.synthetic_part()), "
                        f"never the real objects; got {type(scene).__name__}")
    return scene
