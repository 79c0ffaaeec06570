"""Compositing the synthetic render over the real view camera image."""

from __future__ import annotations

import cv2
import numpy as np


def composite(synthetic_rgb: np.ndarray, alpha: np.ndarray, real_rgb: np.ndarray) -> np.ndarray:
    """The "over" operator: alpha * synthetic + (1 - alpha) * real.

    Real objects are assumed not to occlude synthetic ones. Renders average all rays of a pixel, those that
    miss counting as black, so their colour is already multiplied by alpha: the composite is
    synthetic + (1 - alpha) * real. Where alpha is 0 no synthetic ray hit and the render is black (it has no
    background), so there the composite is the real view.

    Args:
        synthetic_rgb: (H, W, 3) float radiance of the synthetic render, premultiplied by alpha.
        alpha: (H, W) float coverage of the synthetic render in [0, 1].
        real_rgb: (H, W, 3) float radiance of the real view.

    Returns:
        (H, W, 3) float32 composite.
    """
    if synthetic_rgb.shape != real_rgb.shape or alpha.shape != synthetic_rgb.shape[:2]:
        raise ValueError(f"composite: shapes differ: synthetic {synthetic_rgb.shape}, alpha {alpha.shape}, "
                         f"real {real_rgb.shape}")
    out = np.array(real_rgb, np.float32, copy=True)
    # where no synthetic ray hit (alpha 0) the render is black (no background): the composite is the real view.
    # Only the box around the covered pixels is computed (a few per cent of a view: 2 ms instead of 15 at
    # 1024 x 768 on 2 cores), with the same float32 operations in the same order as over the whole image.
    covered = np.asarray(alpha) > 0
    rows = np.flatnonzero(covered.any(axis=1))
    if len(rows) == 0:
        return out
    cols = np.flatnonzero(covered[rows[0]:rows[-1] + 1].any(axis=0))
    ys, xs = slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1)
    keep = 1.0 - np.clip(np.asarray(alpha[ys, xs], np.float32), 0.0, 1.0)
    # per channel through OpenCV: numpy broadcasts over a last axis of 1 several times slower
    out[ys, xs] = cv2.multiply(np.ascontiguousarray(out[ys, xs]), cv2.merge([keep, keep, keep]))
    out[ys, xs] += np.asarray(synthetic_rgb[ys, xs], np.float32)
    return out
