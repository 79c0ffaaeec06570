"""Shared geometry: homographies, rotations, planes and the view camera's pinhole model (OpenCV conventions).

Every module that maps points through a homography, turns a frame, places a board or casts a view camera ray
calls these; none re-types them.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = ["apply_homography", "backproject", "crosses_rectangle", "env_directions", "env_solid_angles", "in_window",
           "pixel_rays", "plane_axes", "project", "rectangle_to_world", "rigid", "rigid_points", "rigid_points_back",
           "rigid_vectors", "rotation_2d", "rotation_matrix", "rotation_xy", "rotation_z", "view_camera"]


def apply_homography(H: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N, 2) points through a (3, 3) homography -> (N, 2) float64 (NaN where the point goes to infinity)."""
    p = np.asarray(points, np.float64).reshape(-1, 2)
    q = np.concatenate([p, np.ones((len(p), 1))], axis=1) @ np.asarray(H, np.float64).T
    with np.errstate(divide="ignore", invalid="ignore"):
        return q[:, :2] / q[:, 2:3]


def rigid(matrix, name: str = "matrix") -> np.ndarray:
    """``matrix`` as a (4, 4) float64 rigid transform, or a ValueError naming ``name``."""
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape != (4, 4) or not np.allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3), atol=1e-9):
        raise ValueError(f"{name} must be a (4, 4) rigid transform, got shape {m.shape}")
    return m


def rigid_points(m: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N, 3) points through the (4, 4) rigid transform ``m``: R p + t."""
    return np.asarray(points) @ m[:3, :3].T + m[:3, 3]


def rigid_points_back(m: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N, 3) points through the inverse of the (4, 4) rigid transform ``m``: R^T (p - t)."""
    return (np.asarray(points) - m[:3, 3]) @ m[:3, :3]


def rigid_vectors(m: np.ndarray, vectors: np.ndarray, *, back: bool = False) -> np.ndarray:
    """(N, 3) directions turned by the (4, 4) rigid transform ``m`` (R v), or by its inverse with ``back`` (R^T v)."""
    return np.asarray(vectors) @ (m[:3, :3] if back else m[:3, :3].T)


def rotation_2d(theta: float) -> np.ndarray:
    """(2, 2) rotation by ``theta`` radians (counter-clockwise)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def rotation_z(theta: float) -> np.ndarray:
    """(3, 3) rotation about the z axis by ``theta`` radians."""
    m = np.eye(3)
    m[:2, :2] = rotation_2d(theta)
    return m


def rotation_xy(tilt: tuple[float, float]) -> np.ndarray:
    """Rotation about the x axis by ``tilt[0]``, then about the y axis by ``tilt[1]`` (radians).

    Returns:
        (3, 3) float64 rotation matrix ``R_y @ R_x``.
    """
    return Rotation.from_euler("xy", [float(tilt[0]), float(tilt[1])]).as_matrix()


def rotation_matrix(euler_deg) -> np.ndarray:
    """Rotation about the world x axis by ``euler_deg[0]``, then y by ``euler_deg[1]``, then z by ``euler_deg[2]``
    (degrees; the scene format's ``rotate_deg``).

    Returns:
        (3, 3) float64 rotation matrix ``R_z @ R_y @ R_x`` (scipy's extrinsic ``"xyz"``).
    """
    return Rotation.from_euler("xyz", np.asarray(euler_deg, np.float64).reshape(3), degrees=True).as_matrix()


def plane_axes(normal) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Right-handed in-plane axes of a plane with this normal: ``ex`` horizontal (perpendicular to world y where
    the normal allows), ``ey = normal x ex``.

    Args:
        normal: (3,) or (N, 3) normals (need not be unit).

    Returns:
        ex, ey, n: unit vectors of the normal's shape.
    """
    n = np.asarray(normal, np.float64)
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    helper = np.where(np.abs(n[..., 1:2]) < 0.9, [0.0, 1.0, 0.0], [1.0, 0.0, 0.0])
    ex = np.cross(helper, n)
    ex /= np.linalg.norm(ex, axis=-1, keepdims=True)
    return ex, np.cross(n, ex), n


def rectangle_to_world(centre, normal, size) -> np.ndarray:
    """(4, 4) ``to_world`` of a Mitsuba ``rectangle`` ([-1, 1]^2 in z = 0, normal +z) of ``size`` = (width,
    height) metres centred at ``centre`` (3,) with unit ``normal`` (3,), its width along :func:`plane_axes`'s ex."""
    ex, ey, n = plane_axes(normal)
    m = np.eye(4)
    m[:3, :3] = np.stack([ex * size[0] / 2, ey * size[1] / 2, n], axis=1)
    m[:3, 3] = np.asarray(centre, np.float64)
    return m


def view_camera(view) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """OpenCV pinhole model of the view camera (``lftransfer.scenes.ViewConfig``).

    Returns:
        K (3, 3) pixels, R (3, 3) world -> camera rotation, t (3,) such that ``x_cam = R X + t`` (x right,
        y down, z forward); pixel (0, 0) is the centre of the top-left pixel. It is the geometry of Mitsuba's
        ``perspective`` sensor of :func:`lftransfer.render.camera.sensor_dict` (horizontal field of view).
    """
    w, h = view.resolution
    origin, target, up = (np.asarray(v, np.float64) for v in (view.origin, view.target, view.up))
    fwd = (target - origin) / np.linalg.norm(target - origin)
    left = np.cross(up, fwd)
    left /= np.linalg.norm(left)
    upv = np.cross(fwd, left)
    R = np.stack([-left, -upv, fwd])
    fx = 0.5 * w / np.tan(np.radians(view.fov_deg) / 2)
    K = np.array([[fx, 0.0, 0.5 * w - 0.5], [0.0, fx, 0.5 * h - 0.5], [0.0, 0.0, 1.0]])
    return K, R, -R @ origin


def project(view, X: np.ndarray) -> np.ndarray:
    """(N, 3) world points -> (N, 2) view camera pixels."""
    K, R, t = view_camera(view)
    x = np.asarray(X, np.float64).reshape(-1, 3) @ R.T + t
    return apply_homography(K, x[:, :2] / x[:, 2:3])


def pixel_rays(view, px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2) view camera pixels -> ((3,) the camera's centre, (N, 3) unit world directions of their rays)."""
    K, R, t = view_camera(view)
    px = np.asarray(px, np.float64).reshape(-1, 2)
    rays = np.concatenate([px, np.ones((len(px), 1))], 1) @ np.linalg.inv(K).T @ R
    return -R.T @ t, rays / np.linalg.norm(rays, axis=1, keepdims=True)


def backproject(view, px: np.ndarray, point, normal) -> np.ndarray:
    """(N, 2) view camera pixels -> (N, 3) world points where their rays meet the plane (point, normal)."""
    centre, rays = pixel_rays(view, px)
    point, normal = np.asarray(point, np.float64), np.asarray(normal, np.float64)
    lam = ((point - centre) @ normal) / (rays @ normal)
    return centre + lam[:, None] * rays


def env_directions(width: int, height: int) -> np.ndarray:
    """(H, W, 3) unit directions of an equirectangular environment map's samples, Mitsuba's ``envmap`` convention
    (so a map lights a render as it is; Mitsuba reads it bilinearly between these samples): row i, column j is
    ``theta = pi i / (H - 1)`` from +y (the first row the zenith, the last the nadir) and
    ``phi = 2 pi (j + 0.5) / W``, ``(sin phi sin theta, cos theta, -cos phi sin theta)``."""
    theta = np.pi * np.arange(height) / (height - 1)
    phi = 2 * np.pi * (np.arange(width) + 0.5) / width
    t, p = np.meshgrid(theta, phi, indexing="ij")
    return np.stack([np.sin(p) * np.sin(t), np.cos(t), -np.cos(p) * np.sin(t)], axis=-1)


def env_solid_angles(width: int, height: int) -> np.ndarray:
    """(H, W) steradians each sample of :func:`env_directions` stands for: the band of theta halfway to the rows
    beside it (half a row at either pole), a W-th of it around; they sum to 4 pi."""
    step = np.pi / (height - 1)
    theta = step * np.arange(height)
    lo, hi = np.clip(theta - step / 2, 0, np.pi), np.clip(theta + step / 2, 0, np.pi)
    band = 2 * np.pi * (np.cos(lo) - np.cos(hi)) / width
    return np.repeat(band[:, None], width, axis=1)


def crosses_rectangle(origins, directions, extent: tuple[float, float, float, float]) -> np.ndarray:
    """(...) bool: whether each ray from ``origins`` along ``directions`` ((..., 3), broadcast together; the lens
    array's frame) meets the plane z = 0 ahead of it inside ``extent`` (xmin, xmax, ymin, ymax): the array's
    rectangle (:meth:`~lftransfer.optics.LensArray.extent`)."""
    o, d = np.asarray(origins, np.float64), np.asarray(directions, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -o[..., 2] / d[..., 2]
        x, y = o[..., 0] + t * d[..., 0], o[..., 1] + t * d[..., 1]
    xmin, xmax, ymin, ymax = extent
    return (t > 0) & (x >= xmin) & (x <= xmax) & (y >= ymin) & (y <= ymax)


def in_window(directions, a: float) -> np.ndarray:
    """(...) bool: whether each direction ((..., 3)) lies in a lenslet's window, |u| and |v| <= ``a`` with
    (u, v) = (d_x / d_z, d_y / d_z) (either side of the array: the sign of d_z is the caller's)."""
    d = np.asarray(directions, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return (np.abs(d[..., 0] / d[..., 2]) <= a) & (np.abs(d[..., 1] / d[..., 2]) <= a)
