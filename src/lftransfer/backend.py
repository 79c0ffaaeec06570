"""The process's compute back-end, set up once at run time: the Mitsuba / Dr.Jit variant, and the BLAS threads
beside it.

``cuda_ad_rgb`` is used when an NVIDIA GPU is usable, ``llvm_ad_rgb`` otherwise; ``LFT_VARIANT`` overrides.
Every module that needs Mitsuba calls :func:`mitsuba` instead of importing it and setting a variant itself.

The BLAS libraries that NumPy, SciPy and OpenCV bring (each its own OpenBLAS) start one thread per core, and
OpenBLAS's threads keep spinning for a while after every matrix product: on two cores they took the cores from
the Dr.Jit kernels that followed and cost the pipeline a quarter of its speed (docs/performance.md, "BLAS threads
beside Dr.Jit"). :func:`bound_blas` bounds them, process-wide, to :func:`blas_threads`
(:data:`lftransfer.choices.DEFAULT_BLAS_THREADS` unless ``lft --blas-threads`` or ``LFT_BLAS_THREADS`` says
otherwise). :func:`mitsuba` applies it when it first selects a variant, and the pipeline's steps apply it again
(about 10 microseconds), so a library that raised the count in between does not slow the frame.
"""

from __future__ import annotations

import logging
import os

from lftransfer import choices

log = logging.getLogger(__name__)
_PREFERENCE = ("cuda_ad_rgb", "llvm_ad_rgb")
BLAS_THREADS_ENV = "LFT_BLAS_THREADS"
_blas_threads: int | None = None    # set_blas_threads (the command line); None: the environment or the default
_blas_controller = None             # threadpoolctl's view of the loaded BLAS libraries, made once
_bounded = False                    # mitsuba() has bounded the BLAS threads once


def mitsuba(variant: str | None = None):
    """Return the ``mitsuba`` module with a rendering variant set.

    Args:
        variant: a Mitsuba variant name; None picks ``$LFT_VARIANT`` or the first that works of
            cuda_ad_rgb, llvm_ad_rgb.

    Returns:
        The imported ``mitsuba`` module.
    """
    import mitsuba as mi

    if not _bounded:
        bound_blas()
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


def set_drjit_threads(threads: int, variant_name: str | None = None) -> None:
    """Give this process's Dr.Jit thread pool ``threads`` threads (>= 1), the variant set first (``variant_name``
    or the default choice, as :func:`mitsuba` makes it)."""
    mitsuba(variant_name)
    import drjit as dr

    dr.set_thread_count(int(threads))


def _check_blas_threads(value, where: str) -> int:
    try:
        n = int(value)
    except (TypeError, ValueError):
        n = -1
    if n < 0 or isinstance(value, bool) or (isinstance(value, float) and not value.is_integer()):
        raise ValueError(f"{where}: expected an integer >= 0 (BLAS threads; 0 leaves the libraries' own default), "
                         f"got {value!r}")
    return n


def blas_threads() -> int:
    """The BLAS threads this process renders beside: the command line's (:func:`set_blas_threads`), else
    ``$LFT_BLAS_THREADS``, else :data:`lftransfer.choices.DEFAULT_BLAS_THREADS`; 0 means the libraries' own
    default (one thread per core), left as it is.

    Raises:
        ValueError: ``LFT_BLAS_THREADS`` is not an integer >= 0 (the message names it).
    """
    if _blas_threads is not None:
        return _blas_threads
    raw = os.environ.get(BLAS_THREADS_ENV, "").strip()
    return choices.DEFAULT_BLAS_THREADS if not raw else _check_blas_threads(raw, BLAS_THREADS_ENV)


def set_blas_threads(threads: int) -> None:
    """Resolve the BLAS threads of this process once (``lft --blas-threads``) and apply them (:func:`bound_blas`).

    Raises:
        ValueError: ``threads`` is not an integer >= 0.
    """
    global _blas_threads
    _blas_threads = _check_blas_threads(threads, "blas_threads")
    bound_blas()


def _controller():
    """threadpoolctl's controller over every BLAS library our dependencies load (NumPy's, SciPy's, OpenCV's),
    made once (about 10 ms: it walks the loaded libraries) after importing the three so that all are found."""
    global _blas_controller
    if _blas_controller is None:
        import cv2  # noqa: F401 - loads OpenCV's OpenBLAS
        import numpy  # noqa: F401
        import scipy.linalg  # noqa: F401 - loads SciPy's OpenBLAS (scipy.sparse alone does not)
        from threadpoolctl import ThreadpoolController

        _blas_controller = ThreadpoolController()
    return _blas_controller


def bound_blas() -> int | None:
    """Bound the threads of every loaded BLAS library to :func:`blas_threads`, process-wide and until changed
    (not restored on return: the whole process renders with Dr.Jit). About 10 microseconds after the first call.

    Returns:
        The bound applied, or None when :func:`blas_threads` is 0 (nothing changed).
    """
    global _bounded
    n = blas_threads()
    _bounded = True
    if n == 0:
        return None
    _controller().limit(limits=n, user_api="blas")
    return n


def blas_thread_counts() -> dict[str, int]:
    """Threads of each BLAS library loaded in this process now, by its file name (a fresh look, not the cached
    controller's: a library loaded since shows too). For reports and tests."""
    from threadpoolctl import threadpool_info

    return {os.path.basename(lib["filepath"]): int(lib["num_threads"])
            for lib in threadpool_info() if lib.get("user_api") == "blas"}
