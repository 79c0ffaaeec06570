"""Compositing the synthetic render over the real view camera image."""

from __future__ import annotations

import cv2
import numpy as np


def composite(synthetic_rgb: np.ndarray, alpha: np.ndarray, real_rgb: np.ndarray) -> np.ndarray:
    """The "over" operator: alpha * synthetic + (1 - alpha) * real.

    Real objects are assumed not to occlude synthetic ones. Renders average all rays of a pixel, those that
    miss counting as black, so their colour is already multiplied by alpha: the composite is
    synthetic + (1 - alpha) * real.

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
    keep = 1.0 - np.clip(np.asarray(alpha, np.float32), 0.0, 1.0)
    # per channel through OpenCV: numpy broadcasts over a last axis of 1 several times slower (the live loop
    # composites every frame); the same float32 operations in the same order
    out = cv2.multiply(np.ascontiguousarray(real_rgb, np.float32), cv2.merge([keep, keep, keep]))
    out += np.asarray(synthetic_rgb, np.float32)
    return out
