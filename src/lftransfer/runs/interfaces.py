"""What a run of a scene with several light field interfaces adds to a run of one (docs/interfaces.md): its
negative control, the same run through the first interface alone, and the report's ``interfaces``."""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

from lftransfer.scenes.interfaces import interface_names

__all__ = ["FIRST_INTERFACE_ONLY", "interfaces_report", "through_first_alone"]

FIRST_INTERFACE_ONLY = "through the first interface alone"   # the negative control's name in the report


def through_first_alone(opened, known, scene, settings, result, gt, step: Callable[[str], None]):
    """The run again through the first interface alone (the others dark), set against the run on the same ground
    truth (:func:`lftransfer.sim.metrics.negative_control`), and the light the exchange adds to the scene's
    ``[effect]`` object (:func:`added_light`).

    Args:
        opened: the rigs (``OpenedRig`` with ``rigs`` and an oracle).
        known: what the run knows of them (``Knowledge`` with ``models``).
        scene: the whole scene.
        settings: the run's ``RunSettings``.
        result: the run's ``TransferResult``.
        gt: the ground truth.
        step: progress.

    Returns:
        (``NegativeControl``, :func:`added_light`'s dict or None).
    """
    from lftransfer.sim.metrics import negative_control
    from lftransfer.transfer.interfaces import run_interfaces

    alt = run_interfaces(opened.rigs, known.models, known.scene, replace(settings.transfer, bounce_views=False),
                         through=[0], progress=lambda msg: step(f"through the first interface alone: {msg}"))
    return negative_control(result, alt, gt, FIRST_INTERFACE_ONLY), added_light(opened.oracle, scene, result, alt, gt)


def added_light(oracle, scene, result, alt, gt) -> dict | None:
    """The scene's ``[effect]`` object ``on`` (a real one): the mean radiance the exchange adds to it, through every
    interface (``result``), through the first alone (``alt``) and in the ground truth (the reflection measure of
    :func:`lftransfer.sim.effects.measure_effect`: each composite against the same without the exchange). None
    without an ``[effect]``."""
    effect = getattr(scene, "effect", None)
    if effect is None:
        return None
    from lftransfer.sim.effects import measure_effect, object_pixels

    pixels = object_pixels(oracle.world, effect.on)
    alone = 0.5 * (gt.composite_alone(0) + gt.composite_alone(1))
    added = {name: measure_effect("reflection", *images, pixels).added_radiance
             for name, images in (("run", (result.composite(), result.composite_direct())),
                                  ("first_interface_only", (alt.composite(), alt.composite_direct())),
                                  ("ground_truth", (gt.image, alone)))}
    return {"on": effect.on, "by": effect.by, "added_radiance": added, "pixels": int(pixels.mask.sum())}


def interfaces_report(scene, result, added: dict | None) -> dict:
    """``report.json``'s ``interfaces``: their names, each one's captured energy per bounce (None for one switched
    off) and :func:`added_light`."""
    return {"names": interface_names(scene.interfaces),
            "real_energy": [None if bounces is None else [b.real_energy for b in bounces]
                            for bounces in result.interfaces],
            "added_light": added}
