"""The benchmark's peer: the same job as our light field renderer, done with Mitsuba's own plugins only.

The synthetic half-space is lit by an incident light field in the paper's point model (docs/architecture.md,
"Radiometry of a lenslet"):
lenslet k is a projective point light at its centre c_k with intensity I_k(w) = L_k(d) A |d_z|, w the
direction of travel (w_z < 0), d = -w, (u, v) = (d_x / d_z, d_y / d_z), L_k bilinear in the grid of
``lightfield.data[k]``. The peer renders the outgoing light field (entry [k, j, i] = radiance arriving at c_k
travelling along +d_ij) with:

- Mitsuba's ``path`` integrator (``max_depth`` = our surface interactions + 1, as Mitsuba counts the camera
  ray's segment too);
- one built-in ``projector`` emitter per lenslet that carries light, at c_k looking along -z, whose texture is
  the irradiance on its image plane at unit distance, T = I cos^3(theta) / (pi scale) (scale = 1);
- one ``batch`` sensor of K ``perspective`` pinhole cameras (camera k at c_k looking along -z, horizontal
  field of view 2 atan(a)), film K U x V, box reconstruction filter; sub-camera k renders columns
  [k U, (k + 1) U) of the film.

Orientation: with ``look_at(c, c - z, up = +y)`` Mitsuba's image row 0 is the +y side of the camera frame and
column 0 its -x side (Mitsuba's camera x axis is "left"). For a projector emitting along w and a camera looking
along -d alike, row r is the grid's row j = r (v_0 = -a first) and column c is the grid's column U - 1 - c: the
columns are reversed, the rows are not. ``tests/runs/bench/test_peer.py`` checks this against our renderer.

The path integrator picks ONE emitter at random per light sample, so its noise grows with the number of
lenslets; our renderer sums all lenslets at every shading point. Its camera samples are jittered over each
pixel (box filter), i.e. it estimates the pixel-averaged radiance, where our renderer samples the pixel centre
direction: at silhouettes the two differ by a bias that no spp removes (:func:`spp_for_rmse` then reports
``max_spp`` as a lower bound).

:func:`peer_comparison` sets the peer against the live step's own renderer on that job (the light field render
alone, point model, the scene's light field samples), at equal RMSE against the converged light field. It is a
renderer comparison, not a timing of the live step: Mitsuba's plugins have no direction-dependent area emitter,
so the area model the demo uses has no peer.
"""

from __future__ import annotations

import math
import statistics
import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from lftransfer.backend import mitsuba
from lftransfer.lightfield import LightField
from lftransfer.render.shapes import scene_dict

__all__ = ["PeerRenderer", "PeerComparison", "footprint_average", "peer_comparison", "rmse", "spp_for_rmse",
           "projector_texture"]


def _bilinear_grid(data: np.ndarray, a: float, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear lookup of one lenslet's grid ``data`` (V, U, 3) at directions (u, v) (same shape, any).

    Same rule as the renderer's point light: texel centres at the grid samples, clamped at the borders
    (no renormalisation over masked samples), zero outside [-a, a]^2.
    """
    V, U = data.shape[:2]
    fx = np.clip((u + a) * (U / (2 * a)) - 0.5, 0.0, U - 1.0)
    fy = np.clip((v + a) * (V / (2 * a)) - 0.5, 0.0, V - 1.0)
    x0 = np.minimum(np.floor(fx).astype(np.int64), max(U - 2, 0))
    y0 = np.minimum(np.floor(fy).astype(np.int64), max(V - 2, 0))
    x1, y1 = np.minimum(x0 + 1, U - 1), np.minimum(y0 + 1, V - 1)
    tx, ty = (fx - x0)[..., None], (fy - y0)[..., None]
    out = ((1 - tx) * (1 - ty) * data[y0, x0] + tx * (1 - ty) * data[y0, x1]
           + (1 - tx) * ty * data[y1, x0] + tx * ty * data[y1, x1])
    inside = (np.abs(u) <= a) & (np.abs(v) <= a)
    return np.where(inside[..., None], out, 0.0)


def projector_texture(lightfield: LightField, k: int, scale: float = 1.0) -> np.ndarray:
    """Texture of Mitsuba's ``projector`` emitter that makes lenslet k the point model's projective light.

    The projector sits at c_k, looks along -z with up = +y and has the horizontal field of view 2 atan(a).
    Mitsuba's texture is irradiance on the image plane at unit distance: intensity I(w) = pi scale T / cos^3,
    so T = I(w) cos^3(theta) / (pi scale) with I(w) = L_k(d) A cos(theta), d = -w, cos(theta) = |d_z|.
    Mitsuba's pixels are square, so for U != V the radiance is resampled (bilinearly) onto N x N texels,
    N = max(U, V); for U == V the texels are the light field's own samples.

    Args:
        lightfield: the incident light field (radiance travelling along -d into z < 0).
        k: lenslet index.
        scale: the projector's ``scale`` parameter.

    Returns:
        (N, N, 3) float32 texture in Mitsuba's image order (row 0 = v most negative, column 0 = u most
        positive).
    """
    a = float(lightfield.array.half_width)
    data = np.asarray(lightfield.data[k], np.float64)
    if lightfield.U == lightfield.V:
        n = lightfield.U
        uu, vv = np.meshgrid(lightfield.u, lightfield.v)
        radiance = data
    else:
        n = max(lightfield.U, lightfield.V)
        axis = -a + (np.arange(n) + 0.5) * (2 * a / n)
        uu, vv = np.meshgrid(axis, axis)
        radiance = _bilinear_grid(data, a, uu, vv)
    cos = 1.0 / np.sqrt(1.0 + uu**2 + vv**2)
    intensity = radiance * (lightfield.array.aperture_area * cos)[..., None]
    texture = intensity * (cos**3 / (math.pi * scale))[..., None]
    return np.ascontiguousarray(texture[:, ::-1, :], dtype=np.float32)


class PeerRenderer:
    """Mitsuba's path integrator + one `projector` emitter per lenslet + a `batch` sensor of lenslet cameras.

    Args:
        objects: the synthetic half-space's objects (``lftransfer.scenes.ObjectConfig``).
        incident: the incident light field (radiance travelling along -d into z < 0).
        U: angular samples along u of the rendered light field.
        V: angular samples along v (must equal U: Mitsuba's perspective camera has square pixels).
        max_depth: surface interactions per path like ours (1 = direct light only).

    Example:
        >>> peer = PeerRenderer(scene.synthetic, captured, 48, 48, max_depth=1)  # doctest: +SKIP
        >>> lf = peer.render(spp=64)                                             # doctest: +SKIP
    """

    def __init__(self, objects: Sequence, incident: LightField, U: int, V: int, *, max_depth: int = 3) -> None:
        U, V, max_depth = int(U), int(V), int(max_depth)
        if U < 1 or V < 1:
            raise ValueError(f"U and V must be positive, got U={U}, V={V}")
        if U != V:
            raise ValueError(f"the peer needs a square angular grid (Mitsuba's pixels are square), got U={U}, V={V}")
        if max_depth < 1:
            raise ValueError(f"max_depth must be >= 1, got {max_depth}")
        mi = mitsuba()
        self.objects = list(objects)
        self.incident = incident
        self.array = incident.array
        self.U, self.V, self.max_depth = U, V, max_depth
        self.K = self.array.K
        a = float(self.array.half_width)
        fov = math.degrees(2.0 * math.atan(a))
        centres = self.array.centres

        data = np.asarray(incident.data)
        peak = np.abs(data).reshape(self.K, -1).max(axis=1)
        self.active_lenslets = np.flatnonzero(peak > 0)

        def look(k: int):
            cx, cy = float(centres[k, 0]), float(centres[k, 1])
            return mi.ScalarTransform4f().look_at(origin=[cx, cy, 0.0], target=[cx, cy, -1.0], up=[0.0, 1.0, 0.0])

        extra: dict = {"integrator": {"type": "path", "max_depth": max_depth + 1, "hide_emitters": True}}
        for k in self.active_lenslets:
            tex = projector_texture(incident, int(k))
            extra[f"lenslet_light_{k:05d}"] = {
                "type": "projector",
                "irradiance": {"type": "bitmap", "bitmap": mi.Bitmap(tex), "raw": True,
                               "filter_type": "bilinear", "wrap_mode": "clamp"},
                "fov": fov, "fov_axis": "x", "scale": 1.0, "to_world": look(int(k)),
            }
        sensor: dict = {
            "type": "batch",
            "film": {"type": "hdrfilm", "width": self.K * U, "height": V, "rfilter": {"type": "box"},
                     "pixel_format": "rgb", "component_format": "float32", "sample_border": False},
            "sampler": {"type": "independent", "sample_count": 1},
        }
        # Zero-padded keys: sub-sensor order is the lenslet order whether Mitsuba keeps insertion or name order.
        for k in range(self.K):
            sensor[f"lenslet_cam_{k:05d}"] = {"type": "perspective", "fov": fov, "fov_axis": "x",
                                              "near_clip": 1e-5, "far_clip": 1e4, "to_world": look(k)}
        extra["lenslet_cameras"] = sensor
        self.scene = mi.load_dict(scene_dict(self.objects, extra=extra), parallel=False, optimize=False)
        self._mask = LightField.zeros(self.array, U, V).mask()

    def render(self, spp: int, seed: int = 0) -> LightField:
        """Render the outgoing light field with ``spp`` samples per light field sample.

        Returns:
            LightField (K, V, U, 3) float32; entries outside ``lf.mask()`` are zero.
        """
        mi = mitsuba()
        spp = int(spp)
        if spp < 1:
            raise ValueError(f"spp must be >= 1, got {spp}")
        lf = LightField.zeros(self.array, self.U, self.V)
        if len(self.active_lenslets) == 0:
            return lf
        image = np.asarray(mi.render(self.scene, spp=spp, seed=int(seed)), dtype=np.float32)  # (V, K U, 3)
        tiles = image[..., :3].reshape(self.V, self.K, self.U, 3).transpose(1, 0, 2, 3)
        lf.data[...] = tiles[:, :, ::-1, :] * self._mask[None, :, :, None]
        return lf


def rmse(a: LightField, b: LightField) -> float:
    """Root-mean-square difference of two light fields over the masked (data) samples, all channels."""
    if a.data.shape != b.data.shape:
        raise ValueError(f"light field shapes differ: {a.data.shape} vs {b.data.shape}")
    mask = a.mask() & b.mask()
    diff = (a.data.astype(np.float64) - b.data.astype(np.float64))[:, mask, :]
    if diff.size == 0:
        return 0.0
    return float(np.sqrt(np.mean(diff**2)))


def spp_for_rmse(peer: PeerRenderer, reference: LightField, target_rmse: float, *, max_spp: int = 4096,
                 repeats: int = 1) -> tuple[int, float, float]:
    """Smallest power-of-two spp at which the peer's RMSE against ``reference`` is at most ``target_rmse``.

    spp = 1, 2, 4, ... up to ``max_spp`` (inclusive when it is a power of two, else the last power below it
    and then ``max_spp``) are rendered with seed 0. At the spp found, the render is timed ``repeats`` times
    after one warm-up render at that spp (which compiles the kernels), each timing ending with
    ``dr.sync_thread()``; the mean is returned.

    Args:
        peer: the peer renderer.
        reference: the light field to match (same array and grid).
        target_rmse: the RMSE to reach (absolute, in the light field's units).
        max_spp: the largest spp tried; if it is not enough, it is returned with its time and RMSE (a lower
            bound of the spp needed).
        repeats: timed renders averaged.

    Returns:
        (spp, seconds per render at that spp, rmse at that spp).
    """
    import drjit as dr

    max_spp = int(max_spp)
    if max_spp < 1:
        raise ValueError(f"max_spp must be >= 1, got {max_spp}")
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    candidates = [1 << e for e in range(max_spp.bit_length()) if (1 << e) <= max_spp]
    if candidates[-1] != max_spp:
        candidates.append(max_spp)
    spp, error = candidates[-1], float("inf")
    for s in candidates:
        spp, error = s, rmse(peer.render(s, seed=0), reference)
        if error <= target_rmse:
            break
    peer.render(spp, seed=1)           # warm-up: the kernels of this spp are compiled and cached
    dr.sync_thread()
    total = 0.0
    for r in range(int(repeats)):
        start = time.perf_counter()
        peer.render(spp, seed=2 + r)
        dr.sync_thread()
        total += time.perf_counter() - start
    return spp, total / int(repeats), error


def footprint_average(renderer, array, lights: Sequence, U: int, V: int, n: int = 4) -> LightField:
    """Light field of pinhole lenslet cameras averaged over each sample's (u, v) footprint (n x n sub-samples).

    This is what a light field render converges to when its rays are spread over the sample's cell, as a
    ``batch`` sensor's pixels are: the common reference of our renderer and the peer.

    Args:
        renderer: a :class:`lftransfer.render.renderer.HalfSpaceRenderer` (exact path) of the objects.
        array: the lens array (frame of the objects).
        lights: the lights.
        U, V: angular samples.
        n: sub-samples per axis of each sample's footprint.

    Returns:
        LightField (K, V, U, 3), masked samples zero.
    """
    lf = LightField.zeros(array, U, V)
    a = array.half_width
    step_u, step_v = 2 * a / U, 2 * a / V
    sub = (np.arange(n) + 0.5) / n - 0.5
    uu = lf.u[None, :, None, None] + step_u * sub[None, None, None, :]     # (1, U, 1, n)
    vv = lf.v[:, None, None, None] + step_v * sub[None, None, :, None]     # (V, 1, n, 1)
    uu, vv = np.broadcast_arrays(uu, vv)                                     # (V, U, n, n)
    d = -np.stack([uu, vv, np.ones_like(uu)], -1)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    K = array.K
    origins = np.zeros((K, V * U * n * n, 3), np.float32)
    origins[..., :2] = array.centres[:, None, :]
    dirs = np.broadcast_to(d.reshape(1, -1, 3), origins.shape)
    radiance, _, _ = renderer.render_rays(origins.reshape(-1, 3), dirs.reshape(-1, 3), lights)
    lf.data[...] = radiance.reshape(K, V, U, n * n, 3).mean(axis=3) * lf.mask()[None, :, :, None]
    return lf


@dataclass(frozen=True)
class PeerComparison:
    """Our renderer against the peer on the light field job (point model), at equal RMSE.

    Attributes:
        ratio: peer_ms / ours_ms (a lower bound where the peer did not reach our RMSE by ``max_spp``).
        ours_ms: median time of the live step's renderer: relight with the captured light field (point model)
            and render the outgoing light field at ``ours_spp`` rays per sample, milliseconds.
        ours_spp: rays per light field sample of ours (the scene's ``render.spp``, as ``lft run`` uses it).
        ours_rmse: RMSE of ours against the converged light field (radiance units); the peer's target.
        peer_ms: time of one peer render at ``peer_spp``, milliseconds.
        peer_spp: the smallest power of two reaching ``ours_rmse`` (or ``max_spp``).
        peer_rmse: the peer's RMSE at ``peer_spp``.
        reached_target: whether the peer reached our RMSE.
        lenslets_lit: lenslets carrying light (one ``projector`` emitter each).
    """

    ratio: float
    ours_ms: float
    ours_spp: int
    ours_rmse: float
    peer_ms: float
    peer_spp: int
    peer_rmse: float
    reached_target: bool
    lenslets_lit: int


def peer_comparison(renderer, array, captured: LightField, *, spp: int, seed: int = 0, repeats: int = 3,
                    max_spp: int = 4096, progress: Callable[[str], None] | None = None) -> PeerComparison:
    """Time the live step's renderer and the peer on the same light field job, at equal RMSE.

    Args:
        renderer: the renderer the live step uses (``LiveTransfer.side.renderer``), its objects posed in the
            array's frame.
        array: the lens array of the rig model the step uses.
        captured: the light field the step decoded (lights the synthetic half-space, point model).
        spp: our rays per light field sample.
        seed: Monte Carlo seed of ours.
        repeats: timed renders of ours (>= 1, after one warm-up); a new light each time, so each relights.
        max_spp: the largest peer sample count tried.
        progress: called with a message per step.

    Returns:
        :class:`PeerComparison`.
    """
    import drjit as dr

    from lftransfer.render.lights import LightFieldLight
    from lftransfer.render.selection import make_renderer

    say = progress or (lambda _m: None)
    U, V = captured.U, captured.V
    objects = list(renderer.objects)

    def ours() -> tuple[LightField, float]:
        light = LightFieldLight(captured, side="synthetic", model="point")
        start = time.perf_counter()
        lf = renderer.render_lightfield(array, [light], U, V, model="point", spp=spp, seed=seed)
        dr.sync_thread()
        return lf, time.perf_counter() - start

    say("peer: converged point-model light field (exact path, averaged over each sample's footprint)")
    light = LightFieldLight(captured, side="synthetic", model="point")
    reference = footprint_average(make_renderer(objects, "exact", 1), array, [light], U, V)
    say("peer: our renderer on the same job (point model)")
    lf, _ = ours()                                             # warm-up: kernels compiled
    ours_s = statistics.median(ours()[1] for _ in range(max(1, int(repeats))))
    target = rmse(lf, reference)
    peer = PeerRenderer(objects, captured, U, V, max_depth=1)
    say(f"peer: Mitsuba path + {len(peer.active_lenslets)} projector emitters, spp for RMSE {target:.3g}")
    peer_spp, peer_s, peer_rmse = spp_for_rmse(peer, reference, target, max_spp=max_spp)
    return PeerComparison(ratio=round(peer_s / ours_s, 2), ours_ms=round(1000 * ours_s, 2), ours_spp=int(spp),
                          ours_rmse=float(target), peer_ms=round(1000 * peer_s, 2), peer_spp=int(peer_spp),
                          peer_rmse=float(peer_rmse), reached_target=bool(peer_rmse <= target),
                          lenslets_lit=int(len(peer.active_lenslets)))
