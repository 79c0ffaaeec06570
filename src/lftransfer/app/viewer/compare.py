"""The page's A/B comparison: the path-traced ground truth of the frame on the screen, rendered on demand on a
thread of its own while the live loop goes on (simulated rig only: the ground truth needs its hidden world).

The comparison keeps the frame's composite as it was when asked for, so the A/B view compares the same moment
however far the loop has moved on; it sends both images at one display scale, their absolute difference brightened
by a stated gain, and the PSNR over the whole view and over the pixels the objects cover
(:func:`lftransfer.sim.metrics.psnr`, :func:`~lftransfer.sim.metrics.object_mask`). The ground truth is a preview at
:data:`GT_SPP` samples per pixel, not the measurement ``lft run`` makes: the message says how noisy it is.
"""

from __future__ import annotations

import base64
import logging
import threading
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = ["GT_SPP", "Comparison", "GroundTruthCompare"]

log = logging.getLogger(__name__)
GT_SPP = 64                  # samples per pixel of the page's ground truths (previews, not measurements): the
                             # "ground truth" layer's and the comparison's
DIFFERENCE_GAIN = 4.0        # the difference image is shown this much brighter than the images


@dataclass(frozen=True)
class Comparison:
    """A frame and its ground truth, ready for the page.

    Attributes:
        frame_index, time_s: the frame compared (its index and scene time).
        composite, ground_truth, difference: JPEG bytes at one display scale (the difference x ``gain``).
        gain: the difference image's brightening.
        psnr_db, psnr_objects_db: PSNR of the composite against the ground truth, whole view and objects only.
        noise_psnr_db: PSNR of the ground truth's two independent halves against each other over the objects: how
            noisy the preview reference is (a composite closer than this cannot be told from it).
        spp: samples per pixel of the ground truth.
        elapsed_s: seconds the ground truth took (the loop ran meanwhile).
        error: why it failed (everything else empty), or None.
    """

    frame_index: int
    time_s: float
    composite: bytes = b""
    ground_truth: bytes = b""
    difference: bytes = b""
    gain: float = DIFFERENCE_GAIN
    psnr_db: float | None = None
    psnr_objects_db: float | None = None
    noise_psnr_db: float | None = None
    spp: int = GT_SPP
    elapsed_s: float = 0.0
    error: str | None = None

    def message(self) -> dict:
        def url(data: bytes) -> str | None:
            return "data:image/jpeg;base64," + base64.b64encode(data).decode("ascii") if data else None

        def db(x: float | None) -> float | None:
            return None if x is None or not np.isfinite(x) else round(float(x), 2)

        return {"type": "compare", "frame_index": self.frame_index, "time_s": round(self.time_s, 3),
                "composite": url(self.composite), "ground_truth": url(self.ground_truth),
                "difference": url(self.difference), "gain": self.gain, "psnr_db": db(self.psnr_db),
                "psnr_objects_db": db(self.psnr_objects_db), "noise_psnr_db": db(self.noise_psnr_db),
                "spp": self.spp, "elapsed_s": round(self.elapsed_s, 2), "error": self.error}


class GroundTruthCompare:
    """One on-demand comparison at a time.

    Args:
        oracle: the simulated rig's :class:`~lftransfer.sim.oracle.Oracle`.
        to_jpeg: (H, W, 3) linear radiance, display scale -> JPEG bytes (the page's own tone mapping).
    """

    def __init__(self, oracle, to_jpeg: Callable[[np.ndarray, float], bytes]) -> None:
        self.oracle = oracle
        self.to_jpeg = to_jpeg
        self._thread: threading.Thread | None = None
        self.last: Comparison | None = None

    @property
    def busy(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def request(self, frame_index: int, time_s: float, composite: np.ndarray, world, scale: float,
                on_done: Callable[[Comparison], None]) -> bool:
        """Render the ground truth of ``world`` (the simulated world as it stands at the frame) in the background
        and hand the comparison with ``composite`` to ``on_done``; False when one is running already."""
        if self.busy:
            return False
        composite = np.array(composite, np.float32, copy=True)

        def run() -> None:
            from lftransfer.sim.metrics import object_mask, psnr

            t0 = time.perf_counter()
            try:
                gt = self.oracle.ground_truth(spp=GT_SPP, world=world, use_cache=False)
                ref = gt.image
                mask = object_mask(gt, 1)
                half = psnr(gt.union[0], gt.union[1], peak=float(ref.max()), mask=mask)
                result = Comparison(
                    frame_index=frame_index, time_s=time_s, composite=self.to_jpeg(np.clip(composite, 0, None), scale),
                    ground_truth=self.to_jpeg(ref, scale),
                    difference=self.to_jpeg(np.abs(composite - ref), scale * DIFFERENCE_GAIN),
                    psnr_db=psnr(composite, ref), psnr_objects_db=psnr(composite, ref, mask=mask),
                    # the halves differ by twice one half's noise variance, their mean has half of it: 4x, 6 dB
                    noise_psnr_db=half + 10.0 * np.log10(4.0) if np.isfinite(half) else None,
                    elapsed_s=time.perf_counter() - t0)
            except Exception as exc:  # noqa: BLE001 - shown on the page; the loop goes on
                log.warning("ground truth failed", exc_info=True)
                result = Comparison(frame_index=frame_index, time_s=time_s, elapsed_s=time.perf_counter() - t0,
                                    error=f"ground truth failed: {type(exc).__name__}: {exc}")
            self.last = result
            on_done(result)

        self._thread = threading.Thread(target=run, name="lft-compare", daemon=True)
        self._thread.start()
        return True
