"""The light around the real scene from a mirror ball the view camera photographs: a light probe (paper, section
6: "by placing a light probe in the scene, environment mapping can be used to incorporate more complex direct
lighting"; docs/architecture.md, "The light probe").

A mirror ball of known radius at a known place reflects, at each point of the half the camera sees, the light
arriving from one direction: the one into which the surface turns the camera's ray. For every direction of an
equirectangular map the point is found (the normal halfway between that direction and the way back to the camera,
refined a few times, since the way back depends on the point), projected into the view camera's image, and read
there; over the ball's reflectance that is the radiance arriving from that direction. Directions the ball cannot
show (the cone behind it, hidden by the ball itself, and the edge of the disc, where a pixel spans many
directions) are left out.

The map uses Mitsuba's ``envmap`` convention, so it lights a render as it is: row i, column j is the direction with
``theta = pi (i + 0.5) / H`` from +y and ``phi = 2 pi (j + 0.5) / W``, ``(sin phi sin theta, cos theta,
-cos phi sin theta)`` (world frame; the scene's y is up).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from lftransfer.optics.geometry import view_camera

__all__ = ["EnvironmentMap", "MirrorBall", "env_directions", "unwrap_mirror_ball"]

NEWTON_STEPS = 6           # refinements of each direction's point on the ball
MIN_FACING = 0.2           # a point of the ball is read where its normal faces the camera at least this much (cosine):
                           # towards the disc's edge one pixel spans too many directions


@dataclass(frozen=True)
class MirrorBall:
    """A mirror ball in the real scene.

    Attributes:
        centre: (3,) world metres.
        radius: metres.
        reflectance: (3,) its mirror reflectance per channel (a chrome ball: about 0.6 to 0.9).
    """

    centre: tuple[float, float, float]
    radius: float
    reflectance: tuple[float, float, float] = (1.0, 1.0, 1.0)


@dataclass(frozen=True)
class EnvironmentMap:
    """Radiance arriving at a point from every direction, equirectangular (Mitsuba's ``envmap`` convention).

    Attributes:
        radiance: (H, W, 3) float32, W m^-2 sr^-1 (0 where not ``valid``).
        valid: (H, W) bool, the directions measured.
    """

    radiance: np.ndarray
    valid: np.ndarray

    def solid_angles(self) -> np.ndarray:
        """(H, W) steradians of each texel."""
        h, w = self.valid.shape
        theta = np.pi * (np.arange(h) + 0.5) / h
        return np.repeat((np.sin(theta) * (np.pi / h) * (2 * np.pi / w))[:, None], w, axis=1)

    def power(self, where: np.ndarray | None = None) -> np.ndarray:
        """(3,) the radiance integrated over the valid directions (``where``: also within this mask), W m^-2."""
        m = self.valid if where is None else self.valid & where
        return (self.radiance * (self.solid_angles() * m)[..., None]).sum(axis=(0, 1))

    def brightest_direction(self) -> np.ndarray:
        """(3,) unit direction of the valid texel with the most radiance (summed over channels)."""
        grey = np.where(self.valid, self.radiance.sum(-1), -np.inf)
        i, j = np.unravel_index(np.argmax(grey), grey.shape)
        return env_directions(*self.valid.shape[::-1])[i, j]


def env_directions(width: int, height: int) -> np.ndarray:
    """(H, W, 3) unit world directions of an equirectangular map's texel centres (the module's convention)."""
    theta = np.pi * (np.arange(height) + 0.5) / height
    phi = 2 * np.pi * (np.arange(width) + 0.5) / width
    t, p = np.meshgrid(theta, phi, indexing="ij")
    return np.stack([np.sin(p) * np.sin(t), np.cos(t), -np.cos(p) * np.sin(t)], axis=-1)


def unwrap_mirror_ball(image: np.ndarray, view, ball: MirrorBall, width: int = 128, height: int = 64
                       ) -> EnvironmentMap:
    """The environment map a mirror ball shows the view camera (see the module's docstring).

    Args:
        image: (H, W, 3) the view camera's linear radiance (an HDR image: a view camera's frames are linear).
        view: the view camera (``ViewConfig``), as calibrated.
        ball: where the ball is and what it reflects.
        width, height: the map's size (height = width / 2 for square texels at the equator).

    Returns:
        :class:`EnvironmentMap`; a direction is valid where its point of the ball faces the camera at least
        :data:`MIN_FACING` (cosine) and lands inside the image.
    """
    K, R, t = view_camera(view)
    eye = -R.T @ t
    c = np.asarray(ball.centre, np.float64)
    r = float(ball.radius)
    omega = env_directions(width, height).reshape(-1, 3)
    back = eye - c
    n = omega + back / np.linalg.norm(back)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    for _ in range(NEWTON_STEPS):            # the way back to the camera depends on the point: refine
        p = c + r * n
        v = eye - p
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        n = omega + v
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    p = c + r * n
    v = eye - p
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    facing = np.einsum("ij,ij->i", n, v)
    cam = p @ R.T + t
    px = cam[:, :2] / cam[:, 2:3] @ K[:2, :2].T + K[:2, 2]
    h_img, w_img = image.shape[:2]
    valid = (facing >= MIN_FACING) & (cam[:, 2] > 0) & (px[:, 0] >= 0) & (px[:, 0] <= w_img - 1) \
        & (px[:, 1] >= 0) & (px[:, 1] <= h_img - 1)
    maps = px.astype(np.float32).reshape(height, width, 2)
    seen = cv2.remap(np.ascontiguousarray(image, np.float32), maps[..., 0], maps[..., 1], cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    radiance = seen / np.asarray(ball.reflectance, np.float32)
    valid = valid.reshape(height, width)
    return EnvironmentMap(np.where(valid[..., None], radiance, 0.0).astype(np.float32), valid)
