"""What the fast path approximates, measured on the live step's own frame: its composite against the exact path's.

The step's composite (rendered with the renderer the settings pick, usually the fast path's irradiance cache) is
compared with the composite the exact path (:class:`lftransfer.render.renderer.HalfSpaceRenderer`: every lenslet
summed at every ray, shadow rays, the scene's ``max_depth``) renders from the same decoded light field, the same
virtual point light, the same lighting model and reconstruction, over the same real view; for the area model
with a dense aperture sampling. What differs is what the fast path approximates (irradiance interpolated over a
cache triangle, the light synthetic objects exchange gathered per cache point and only its diffuse part) and the
step's own aperture and pixel sampling.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from lftransfer.composite import composite
from lftransfer.render.selection import make_renderer
from lftransfer.sim.metrics import psnr

__all__ = ["FastVsExact", "fast_vs_exact"]


@dataclass(frozen=True)
class FastVsExact:
    """The step's composite against the exact path's.

    Attributes:
        psnr_db: PSNR of the step's composite against the exact one (peak: the exact composite's maximum), dB;
            None where the step renders with the exact path itself (nothing approximated) or the images are
            identical or dark.
        psnr_objects_db: the same over the pixels the synthetic objects cover (the exact render's coverage:
            where the fast path renders; the rest of the frame is the same real view), same peak, dB; None as
            above or where no synthetic object is in view.
        exact_aperture_samples: aperture points per lenslet of the exact reference (area model).
        exact_spp: rays per view pixel of the exact reference.
        note: what was compared, in words.
    """

    psnr_db: float | None
    psnr_objects_db: float | None
    exact_aperture_samples: int
    exact_spp: int
    note: str


def fast_vs_exact(frame, side, settings, *, aperture_samples: int = 32) -> FastVsExact:
    """Render the exact reference of a live frame and compare composites.

    Args:
        frame: a ``LiveFrame`` (its decoded light field, real view and composite).
        side: the live loop's ``SyntheticSide`` (posed objects, point light, view sensor) at the frame's time.
        settings: the live loop's ``TransferSettings`` (the exact path renders at its ``max_depth``).
        aperture_samples: aperture points per lenslet of the reference (area model; other models use the
            settings' own).

    Returns:
        :class:`FastVsExact`.
    """
    spp = max(4, settings.view_spp)
    if side.renderer.kind != "fast":
        return FastVsExact(None, None, settings.aperture_samples, settings.view_spp,
                           "the step renders with the exact path: nothing is approximated by the fast path")
    samples = int(aperture_samples) if settings.lighting_model == "area" else settings.aperture_samples
    incident = side.incident_light(frame.captured_lf, settings.seed, aperture_samples=samples)
    exact = make_renderer(side.renderer.objects, "exact", settings.max_depth)
    view = exact.render_view(side.sensor, side.width, side.height, [*side.direct_lights, incident], spp=spp,
                             seed=settings.seed)
    reference = composite(view.rgb, view.alpha, frame.real_view)
    peak = float(reference.max())
    value = psnr(frame.composite, reference, peak)
    covered = view.alpha > 0.5
    objects = psnr(frame.composite, reference, peak, mask=covered) if covered.any() else float("nan")
    note = (f"the step's composite (fast path, {settings.view_spp} rays per pixel, {settings.aperture_samples} "
            f"aperture points) against the exact path ({spp} rays per pixel, {samples} aperture points, shadow "
            f"rays at every hit, max_depth {settings.max_depth}), same lights, {settings.lighting_model} model")
    return FastVsExact(round(value, 2) if math.isfinite(value) else None,
                       round(objects, 2) if math.isfinite(objects) else None, samples, spp, note)
