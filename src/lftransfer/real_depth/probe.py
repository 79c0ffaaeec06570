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
``theta = pi i / (H - 1)`` from +y and ``phi = 2 pi (j + 0.5) / W``, ``(sin phi sin theta, cos theta,
-cos phi sin theta)`` (:func:`~lftransfer.optics.geometry.env_directions`; world frame, the scene's y up).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from lftransfer.optics.geometry import crosses_rectangle, env_directions, env_solid_angles, view_camera

__all__ = ["EnvironmentMap", "MirrorBall", "ProbeMeasurement", "env_directions", "fill_environment", "photograph_probe",
           "through_array", "unwrap_mirror_ball"]

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
        """(H, W) steradians of each texel (:func:`~lftransfer.optics.geometry.env_solid_angles`)."""
        h, w = self.valid.shape
        return env_solid_angles(w, h)

    def power(self, where: np.ndarray | None = None) -> np.ndarray:
        """(3,) the radiance integrated over the valid directions (``where``: also within this mask), W m^-2."""
        m = self.valid if where is None else self.valid & where
        return (self.radiance * (self.solid_angles() * m)[..., None]).sum(axis=(0, 1))

    def peak_direction(self, radius_deg: float = 5.0) -> np.ndarray:
        """(3,) unit direction of the brightest spot, finer than a texel: the mean direction of the valid texels
        within ``radius_deg`` of the brightest one, weighted by their power (radiance summed over channels times
        solid angle)."""
        h, w = self.valid.shape
        d = env_directions(w, h)
        near = self.valid & (d @ self.brightest_direction() >= np.cos(np.radians(radius_deg)))
        weight = self.radiance.sum(-1) * self.solid_angles() * near
        mean = (d * weight[..., None]).sum(axis=(0, 1))
        return mean / np.linalg.norm(mean)

    def brightest_direction(self) -> np.ndarray:
        """(3,) unit direction of the valid texel with the most radiance (summed over channels)."""
        grey = np.where(self.valid, self.radiance.sum(-1), -np.inf)
        i, j = np.unravel_index(np.argmax(grey), grey.shape)
        return env_directions(*self.valid.shape[::-1])[i, j]


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


FILL_MARGIN_TEXELS = 1      # the array's outline in the map widened by this much before the map is filled


def through_array(origin, width: int, height: int, extent: tuple[float, float, float, float]) -> np.ndarray:
    """(H, W) bool: the map's directions that, from ``origin`` (3,) in the lens array's frame (real side), cross the
    array's rectangle ``extent`` (xmin, xmax, ymin, ymax) in the plane z = 0: what the ball sees of the rig, not
    of the room."""
    return crosses_rectangle(np.asarray(origin, float), env_directions(width, height), extent)


def fill_environment(env: EnvironmentMap) -> np.ndarray:
    """(H, W, 3) float32 the map with its unmeasured directions filled: each takes the median of the measured
    texels at its elevation (the median, so that a sun in the same row does not spread into the hole), a row with
    none the median of all. Rooms change more with elevation than around it (sky, horizon, ground), so the cone
    behind the ball and the rig's outline become the room around them: a guess, said to be one (the share filled
    is :attr:`ProbeMeasurement.filled_share`)."""
    rgb = np.where(env.valid[..., None], env.radiance, np.nan).astype(np.float32)
    overall = np.nanmedian(rgb.reshape(-1, 3), axis=0) if env.valid.any() else np.zeros(3, np.float32)
    some = env.valid.any(axis=1)
    rows = np.full((env.valid.shape[0], 3), overall, np.float32)
    if some.any():
        rows[some] = np.nanmedian(rgb[some], axis=1)
    return np.where(env.valid[..., None], env.radiance, rows[:, None, :]).astype(np.float32)


@dataclass(frozen=True)
class ProbeMeasurement:
    """What the light probe measured (in the lens array's frame, the synthetic side's).

    Attributes:
        photo: (H, W, 3) float32 the view camera's photograph of the ball, linear radiance.
        measured: the unwrapped map; valid where the ball showed the room (not the rig, not behind the ball).
        radiance: (h, w, 3) float32 the map that lights the synthetic objects: ``measured``, its other directions
            filled (:func:`fill_environment`).
    """

    photo: np.ndarray
    measured: EnvironmentMap
    radiance: np.ndarray

    @property
    def filled(self) -> EnvironmentMap:
        """The map that lights the synthetic objects, every direction valid."""
        return EnvironmentMap(self.radiance, np.ones(self.radiance.shape[:2], bool))

    @property
    def filled_share(self) -> float:
        """The share of the sphere of directions (by solid angle) that was filled, not measured."""
        omega = self.measured.solid_angles()
        return float((omega * ~self.measured.valid).sum() / omega.sum())

    def brightest_direction(self) -> np.ndarray:
        """(3,) unit direction (the array's frame) of the filled map's brightest texel."""
        return self.filled.brightest_direction()

    def summary(self) -> dict:
        """JSON: the map's size, the share measured, its power and brightest direction."""
        return {"map": [int(self.radiance.shape[1]), int(self.radiance.shape[0])],
                "measured_share": round(1.0 - self.filled_share, 4),
                "power_w_m2": [round(float(v), 4) for v in self.filled.power()],
                "brightest_direction": [round(float(v), 4) for v in self.brightest_direction()]}


def photograph_probe(rig, world_centre, ball: MirrorBall, view, extent: tuple[float, float, float, float], *,
                     width: int = 128, quality: int | None = None) -> ProbeMeasurement:
    """Photograph the light probe through the rig and recover the room's light from it.

    The rig is asked for the :class:`~lftransfer.rig.requests.MirrorBall` set-up (the ball on its mount where the
    scene says, ``world_centre`` in the scene's world frame), the view camera photographs it, the photograph is
    unwrapped (:func:`unwrap_mirror_ball`) with ``ball`` and ``view`` as the pipeline knows them in the lens
    array's frame, the directions in which the ball sees the rig (:func:`through_array`, widened by
    :data:`FILL_MARGIN_TEXELS`) are dropped, and the rest filled. The rig is left in the real scene's set-up.

    Args:
        rig: the rig (its :class:`~lftransfer.rig.base.Rig` methods).
        world_centre: (3,) the mount's place, world metres.
        ball: the ball in the lens array's frame (its centre moved there), radius and reflectance.
        view: the view camera (``ViewConfig``) in the lens array's frame, as calibrated.
        extent: (xmin, xmax, ymin, ymax) of the lens array in its frame.
        width: the map's width (its height is half).
        quality: the view camera's samples per pixel for the photograph (a simulated rig's), None: the rig's.

    Returns:
        :class:`ProbeMeasurement`.
    """
    from lftransfer.rig.requests import MirrorBall as BallOnMount, RealScene, ViewCapture

    rig.setup(BallOnMount(tuple(float(v) for v in world_centre), float(ball.radius)))
    rig.project(rig.info.black())
    photo = np.asarray(rig.capture_view(ViewCapture(quality=quality)).radiance, np.float32)
    rig.setup(RealScene())
    env = unwrap_mirror_ball(photo, view, ball, width, width // 2)
    rigged = through_array(ball.centre, width, width // 2, extent)
    if FILL_MARGIN_TEXELS:
        k = np.ones((2 * FILL_MARGIN_TEXELS + 1,) * 2, np.uint8)
        rigged = cv2.dilate(rigged.astype(np.uint8), k).astype(bool)
    measured = EnvironmentMap(np.where(rigged[..., None], 0.0, env.radiance).astype(np.float32), env.valid & ~rigged)
    return ProbeMeasurement(photo=photo, measured=measured, radiance=fill_environment(measured))
