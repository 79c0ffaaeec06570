"""A scene at the sizes the pipeline works at: the check that refuses one too small before any work
(:func:`check_resolution`) and the same scene at a quarter of its sizes, for ``--quick`` (:func:`quick_scene`)."""

from __future__ import annotations

from lftransfer.scenes.loader import SceneError, with_overrides

__all__ = ["MIN_PIXELS_PER_LENSLET", "MIN_VIEW_PIXELS", "QUICK_FACTOR", "check_resolution", "quick_scene"]

QUICK_FACTOR = 4
MIN_VIEW_PIXELS = 8             # the view camera's smaller side (metrics are box-downsampled images of it)
MIN_PIXELS_PER_LENSLET = 2      # LF camera and projector pixels across one lenslet's pitch


def _too_small(scene, factor: int = 1) -> list[str]:
    """What of a scene is below the sizes the pipeline works at, after dividing every device by ``factor``."""
    rig, view = scene.rig, scene.view
    problems = []
    w, h = (v // factor for v in view.resolution)
    if min(w, h) < MIN_VIEW_PIXELS:
        problems.append(f"view.resolution {list(view.resolution)} gives {w} x {h} (at least {MIN_VIEW_PIXELS} "
                        f"pixels a side)")
    spacing = (rig.rows * (3 ** 0.5 / 2 if rig.lattice == "hex" else 1.0) + 1, rig.cols + 0.5)
    for name in ("lf_camera", "projector"):
        size = getattr(rig, name)
        across = min(size[0] // factor / spacing[1], size[1] // factor / spacing[0])
        if across < MIN_PIXELS_PER_LENSLET:
            problems.append(f"rig.{name} {list(size)} gives {size[0] // factor} x {size[1] // factor}, "
                            f"{across:.1f} pixels per lenslet for {rig.rows} x {rig.cols} lenslets (at least "
                            f"{MIN_PIXELS_PER_LENSLET})")
    return problems


def check_resolution(scene, quick: bool = False) -> None:
    """Refuse a scene whose devices are too small for the pipeline, before any work.

    Args:
        scene: ``SceneConfig``.
        quick: check the sizes that ``--quick`` (:func:`quick_scene`) would give.

    Raises:
        SceneError: naming the scene's file, the fields and the sizes.
    """
    problems = _too_small(scene, QUICK_FACTOR if quick else 1)
    if problems:
        name = str(scene.source) if scene.source else "<scene>"
        how = f"--quick divides every device by {QUICK_FACTOR}: " if quick else ""
        raise SceneError(f"{name}: {how}{'; '.join(problems)}" + ("; run it without --quick" if quick and not
                                                                    _too_small(scene) else ""))


def quick_scene(scene):
    """The same scene at a small resolution (for ``--quick``): every device at a quarter size, a third of the
    angular samples (at least 8), a quarter of the ground-truth samples (at least 16).

    Raises:
        SceneError: the quarter sizes are too small (:func:`check_resolution`).
    """
    check_resolution(scene, quick=True)
    rig, view, render = scene.rig, scene.view, scene.render
    return with_overrides(
        scene,
        rig={"lf_camera": [rig.lf_camera[0] // QUICK_FACTOR, rig.lf_camera[1] // QUICK_FACTOR],
             "projector": [rig.projector[0] // QUICK_FACTOR, rig.projector[1] // QUICK_FACTOR],
             "angular_samples": max(8, rig.angular_samples // 3)},
        view={"resolution": [view.resolution[0] // QUICK_FACTOR, view.resolution[1] // QUICK_FACTOR]},
        render={"gt_spp": max(16, render.gt_spp // QUICK_FACTOR)},
    )
