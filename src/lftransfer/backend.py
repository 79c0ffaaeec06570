"""Mitsuba / Dr.Jit variant selection, done once at run time.

``cuda_ad_rgb`` is used when an NVIDIA GPU is usable, ``llvm_ad_rgb`` otherwise; ``LFT_VARIANT`` overrides.
Every module that needs Mitsuba calls :func:`mitsuba` instead of importing it and setting a variant itself.
"""

from __future__ import annotations

import logging
import os

log = logging.getLogger(__name__)
_PREFERENCE = ("cuda_ad_rgb", "llvm_ad_rgb")


def mitsuba(variant: str | None = None):
    """Return the ``mitsuba`` module with a rendering variant set.

    Args:
        variant: a Mitsuba variant name; None picks ``$LFT_VARIANT`` or the first that works of
            cuda_ad_rgb, llvm_ad_rgb.

    Returns:
        The imported ``mitsuba`` module.
    """
    import mitsuba as mi

    wanted = variant or os.environ.get("LFT_VARIANT")
    if wanted:
        if mi.variant() != wanted:
            mi.set_variant(wanted)
        return mi
    if mi.variant() in _PREFERENCE:
        return mi
    errors = []
    for name in _PREFERENCE:
        try:
            mi.set_variant(name)
            import drjit as dr

            if name.startswith("cuda") and not dr.has_backend(dr.JitBackend.CUDA):
                raise RuntimeError("no CUDA device")
            log.info("Mitsuba variant %s", name)
            return mi
        except Exception as exc:  # noqa: BLE001 - try the next variant
            errors.append(f"{name}: {exc}")
    raise RuntimeError("no usable Mitsuba variant: " + "; ".join(errors))


def variant() -> str:
    """Name of the active variant (selecting one first if needed)."""
    return mitsuba().variant()
