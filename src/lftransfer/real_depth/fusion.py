"""The better of several real depths per view pixel (docs/architecture.md, "Occlusion")."""

from __future__ import annotations

import numpy as np

from lftransfer.real_depth.lightfield import ViewDepth

__all__ = ["fuse_depths", "share_taken"]


def fuse_depths(*depths: ViewDepth) -> ViewDepth:
    """Per view pixel the depth whose standard deviation is smallest, among those that have one there.

    Args:
        depths: depth maps of the same view camera (each NaN where it has none).

    Returns:
        :class:`ViewDepth` with source ``"a+b"`` (the sources' names, in order); NaN where none has a depth.
    """
    if not depths:
        raise ValueError("fuse_depths: no depth map given")
    shape = depths[0].depth.shape
    if any(d.depth.shape != shape for d in depths):
        raise ValueError(f"fuse_depths: shapes differ: {[d.depth.shape for d in depths]}")
    sigma = np.stack([np.where(d.known, d.sigma, np.inf) for d in depths])          # (n, H, W)
    pick = np.argmin(sigma, axis=0)
    depth = np.take_along_axis(np.stack([d.depth for d in depths]), pick[None], 0)[0]
    sig = np.take_along_axis(sigma, pick[None], 0)[0]
    known = np.isfinite(sig)
    return ViewDepth(np.where(known, depth, np.nan).astype(np.float32), np.where(known, sig, np.nan).astype(np.float32),
                     "+".join(d.source for d in depths))


def share_taken(fused: ViewDepth, source: ViewDepth) -> float:
    """Of the pixels with a fused depth, the share whose depth came from ``source`` (one of those fused)."""
    known = fused.known
    return float(np.mean(source.known & known & (source.depth == fused.depth)) / max(float(known.mean()), 1e-12))
