"""The light field light: a light field entering one half-space through the lens array, every lenslet an emitter
whose radiance depends on direction only, under the point, area or prefiltered lighting model, read between the
lenslets by the box or linear reconstruction and beyond their window as cut or edge
(:mod:`lftransfer.render.lights`). Shapes of inputs are written as (N,) for N shading points."""

from __future__ import annotations

from typing import Literal, NamedTuple

import numpy as np

from lftransfer.backend import mitsuba
from lftransfer import choices
from lftransfer.choices import LIGHTING_MODELS, RECONSTRUCTIONS, WINDOWS, LightingModel, Reconstruction, Window
from lftransfer.lightfield import LightField
from lftransfer.optics.geometry import rigid, rigid_points, rigid_points_back, rigid_vectors
from lftransfer.lightfield.window import SteepRays, extend_beyond_window, steep_rays
from lftransfer.render.lights.jit import jit_array
from lftransfer.render.lights.sampling import (EDGE_REACH, aperture_points, extended_table, linear_blend,
                                               plane_lookup)
from lftransfer.render.lights.sources import Irradiance, direction_weight

SAMPLING_POOL = 1024        # aperture points of a jittered area model (a stratified pool)


class Incident(NamedTuple):
    """What :meth:`LightFieldLight.incident` finds along rays (all (N,) Dr.Jit arrays).

    Attributes:
        radiance: mi.Color3f, W m^-2 sr^-1 arriving along each ray.
        lenslet: mi.UInt32, the lenslet whose aperture the ray meets, K where none.
        density: mi.Float, per steradian, with which :meth:`LightFieldLight.reflect` draws the ray's direction.
    """

    radiance: object
    lenslet: object
    density: object


def _rigid(pose) -> np.ndarray | None:
    """A light's pose as it keeps it: (4, 4) float64, or None for none or the identity (ValueError where not a rigid
    transform)."""
    if pose is None:
        return None
    m = rigid(pose, "pose")
    return None if np.allclose(m, np.eye(4), rtol=0, atol=1e-15) else m


class LightFieldLight:
    """A light field entering one half-space through the lens array.

    Args:
        lightfield: the light field; for ``side="synthetic"`` a captured real light field (radiance travelling
            along -d into z < 0), for ``side="real"`` a projected one (travelling along +d into z > 0).
        side: which half-space the lit points are in.
        model: ``"point"``, ``"area"`` or ``"prefiltered"`` (module docstring).
        aperture_samples: M, points per lenslet aperture for the area model.
        seed: decorrelates the aperture pattern between lenslets and calls.
        jitter: area model only: each shading point and lenslet takes its M points at a random place in a
            long stratified sequence over the aperture (an unbiased Monte Carlo estimate whose error averages
            out over pixels and samples), instead of the same M points everywhere (a fixed quadrature).
        reconstruction: area model only: ``"box"`` or ``"linear"`` (module docstring).
        window: what arrives from beyond the lenslets' window, ``"cut"`` (nothing) or ``"edge"`` (the window's
            edge; module docstring).
        steep: with ``window="edge"``, which steep samples to read from the window's edge
            (:func:`lftransfer.lightfield.window.steep_rays` at :data:`EDGE_REACH`, with the real scene's depth:
            those whose rays meet a surface); None: all of them.
        pose: (4, 4) rigid transform from the array's own frame (the plane z = 0) to the frame of the points it
            lights (one interface of several, lighting a scene posed in another's frame); None: the same frame.
            Points and directions are carried into the array's frame, the aperture points and shadow rays back.

    Example:
        >>> light = LightFieldLight(captured, side="synthetic", model="area")  # doctest: +SKIP
        >>> radiance = light.illuminate(scene, si, si.is_valid())               # doctest: +SKIP
    """

    def __init__(self, lightfield: LightField, side: Literal["synthetic", "real"],
                 model: LightingModel = choices.DEFAULT_LIGHTING_MODEL,
                 aperture_samples: int = choices.DEFAULT_APERTURE_SAMPLES, seed: int = 0, jitter: bool = True,
                 reconstruction: Reconstruction = choices.LENSLET_RECONSTRUCTION,
                 window: Window = choices.LENSLET_WINDOW, steep: SteepRays | None = None,
                 pose: np.ndarray | None = None) -> None:
        if side not in ("synthetic", "real"):
            raise ValueError(f"side must be 'synthetic' or 'real', got {side!r}")
        if model not in LIGHTING_MODELS:
            raise ValueError(f"lighting model must be one of {LIGHTING_MODELS}, got {model!r}")
        if reconstruction not in RECONSTRUCTIONS:
            raise ValueError(f"reconstruction must be one of {RECONSTRUCTIONS}, got {reconstruction!r}")
        if window not in WINDOWS:
            raise ValueError(f"window must be one of {WINDOWS}, got {window!r}")
        if reconstruction != "box" and model != "area":
            raise ValueError(f"reconstruction {reconstruction!r} needs the area lighting model (the {model!r} "
                             "model reads each lenslet at its centre)")
        if aperture_samples < 1:
            raise ValueError(f"aperture_samples must be >= 1, got {aperture_samples}")
        mi = mitsuba()
        self.lightfield = lightfield
        self.side = side
        self.pose = _rigid(pose)
        self.model = model
        array = lightfield.array
        data = np.ascontiguousarray(lightfield.data, dtype=np.float32)
        self.K, self.V, self.U = data.shape[:3]
        self.a = float(array.half_width)
        self.area = float(array.aperture_area)
        self.reconstruction = reconstruction
        self.window = window
        # Only lenslets that carry light are visited (the background is dark).
        peak = np.abs(data).reshape(self.K, -1).max(axis=1)
        carries = peak > 0
        self._margin = 0       # samples of the table beyond [-a, a] on each side
        edge_table = None
        if window == "edge":
            if steep is None:
                steep = steep_rays(lightfield, EDGE_REACH)
            elif steep.reach != EDGE_REACH:
                raise ValueError(f"steep rays found out to {steep.reach} a, the edge window reads {EDGE_REACH} a")
            if model == "prefiltered":          # the summed-area table of the square, read at clamped (u, v)
                ext = extend_beyond_window(lightfield, steep)
                m = ext.margin
                data = ext.data[:, m:m + self.V, m:m + self.U]
            else:
                edge_table, self._margin = extended_table(data, steep), steep.margin
        if model == "prefiltered":
            # Summed-area table (V+1, U+1) per lenslet and channel: box-filtered lookups in O(1).
            sat = np.zeros((self.K, self.V + 1, self.U + 1, 3), np.float64)
            sat[:, 1:, 1:] = data.astype(np.float64).cumsum(1).cumsum(2)
            self._table = jit_array(mi.Float, sat.astype(np.float32).ravel())
        else:
            self._table = jit_array(mi.Float, data.ravel()) if edge_table is None else edge_table
        centres = array.centres.astype(np.float32)
        self._cx = jit_array(mi.Float, centres[:, 0])
        self._cy = jit_array(mi.Float, centres[:, 1])
        self.M = 1 if model != "area" else aperture_samples
        self.seed = int(seed)
        self.pool = SAMPLING_POOL if (model == "area" and jitter) else self.M
        if model == "area":
            offsets = aperture_points(array, self.pool, int(seed))
        else:
            offsets = np.zeros((1, 2), np.float32)
        self._ox = jit_array(mi.Float, offsets[:, 0])
        self._oy = jit_array(mi.Float, offsets[:, 1])
        if reconstruction == "linear":
            blend = linear_blend(array, self.pool if model == "area" else 0, int(seed))
            carries = carries | (blend.reads & carries[None, :]).any(axis=1)   # a dark lenslet next to a lit one
            self._blend_idx = jit_array(mi.UInt32, blend.index)
            self._blend_w = jit_array(mi.Float, blend.weight)
        self.active_lenslets = np.flatnonzero(carries).astype(np.uint32)
        self._active = jit_array(mi.UInt32, self.active_lenslets)
        self._sends = jit_array(mi.UInt32, np.append(carries, False).astype(np.uint32))   # (K + 1,), K: none

    def may_light(self, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """Which surface points can receive any light through the array at all (a cheap conservative test).

        Args:
            points: (N, 3) positions; normals: (N, 3) unit normals.

        Returns:
            (N,) bool: on this light's side of the plane and facing some part of the array.
        """
        xmin, xmax, ymin, ymax = self.lightfield.array.extent()
        corners = np.array([[xmin, ymin, 0.0], [xmin, ymax, 0.0], [xmax, ymin, 0.0], [xmax, ymax, 0.0]])
        if self.pose is not None:           # into the array's frame
            points, normals = rigid_points_back(self.pose, points), rigid_vectors(self.pose, normals, back=True)
        side = points[:, 2] > 0 if self.side == "real" else points[:, 2] < 0
        facing = (np.einsum("nd,cnd->cn", normals, corners[:, None, :] - points[None]) > 0).any(axis=0)
        return side & facing

    def _plane(self, points, directions, active):
        """Where the rays (x, w) meet the array plane: (raster, meets, raster cell of q, u, v of d, distance)."""
        mi = mitsuba()
        import drjit as dr

        look = plane_lookup(self.lightfield.array, self.reconstruction)
        sign = -1.0 if self.side == "real" else 1.0
        p, w = self._point_in(points), self._vector_in(directions)
        ok = mi.Bool(active) & (p.z * w.z < 0.0)
        t = -p.z / dr.select(ok, w.z, 1.0)
        fx = (p.x + t * w.x - look.x0) / look.cell
        fy = (p.y + t * w.y - look.y0) / look.cell
        ok &= (fx >= 0.0) & (fy >= 0.0) & (fx < look.nx) & (fy < look.ny)
        cell = mi.UInt32(dr.floor(fy)) * look.nx + mi.UInt32(dr.floor(fx))
        d = sign * w
        u = d.x / dr.select(ok, d.z, 1.0)
        v = d.y / dr.select(ok, d.z, 1.0)
        return look, ok, cell, u, v, t

    def incident(self, points, directions, active):
        """Radiance that the area lenslets send to ``points`` from along ``directions`` (no occlusion test).

        The ray from x along w meets the array plane at q; the light arriving is lenslet k(q)'s radiance in
        direction d = w (synthetic side) or -w (real side), k(q) the lenslet whose aperture contains q
        (``"box"``), or the blend of the three lenslets around q (``"linear"``): what ``illuminate`` integrates
        over the apertures, given per direction, so that a caller can integrate it against a BSDF lobe (the fast
        path's glossy reflection, :mod:`lftransfer.render.fast`). k(q) is found in a raster of the array plane
        with cells of pitch / 64 (:func:`plane_lookup`).

        Args:
            points: mi.Point3f (N,) positions x, metres, on this light's side of the plane.
            directions: mi.Vector3f (N,) unit directions w from x towards the array.
            active: mi.Bool (N,).

        Returns:
            :class:`Incident`: the radiance (zero where the ray misses the apertures or leaves the lenslets'
            window |u|, |v| > a, with ``window="edge"`` their reach |(u, v)| > EDGE_REACH a), the lenslet k(q) (K
            where none) and the density with which :meth:`reflect` draws this direction, M r^2 / (A cos_p) where
            k(q) sends light, else 0.

        Raises:
            ValueError: a ``"point"`` or ``"prefiltered"`` light (its lenslets are points, seen along no
                direction in particular).
        """
        mi = mitsuba()
        import drjit as dr

        if self.model != "area":
            raise ValueError(f"incident radiance along a direction needs the area lighting model, got {self.model!r}")
        look, ok, cell, u, v, t = self._plane(points, directions, active)
        radiance = mi.Color3f(0.0)
        for j in range(look.terms):
            weight = dr.gather(mi.Float, look.weights, cell * 3 + j, ok)
            k = dr.gather(mi.UInt32, look.lenslets, cell * 3 + j, ok)
            radiance += weight * self._bilinear(k, u, v, ok & (weight > 0.0))
        own = dr.select(ok, dr.gather(mi.UInt32, look.own, cell, ok), self.K)
        sends = ok & (dr.gather(mi.UInt32, self._sends, own, ok) != 0)
        density = self.M * dr.square(t) / (self.area * dr.maximum(dr.abs(self._vector_in(directions).z), 1e-8))
        return Incident(dr.select(ok, radiance, 0.0), own, dr.select(sends, density, 0.0))

    def reflect(self, si, active, ctx, visibility, lobe_samples: int = 0, seed: int = 0):
        """Light from every lenslet reflected towards ``-si.wi`` by the BSDF components ``ctx`` enables, with
        occlusion read from a cache instead of shadow rays (the fast path's glossy lobes).

        Each lenslet that sends light is read at the points of its aperture that ``illuminate`` reads (area
        model: M points of the stratified pool from a random start per shading point; point and prefiltered
        models: its centre), each weighted by ``visibility(k)`` instead of a shadow ray. With ``lobe_samples`` =
        n_b > 0 (area model), the caller also draws n_b directions from the BSDF, and this sum takes the balance
        heuristic's share p_l / (p_l + n_b p_b) of each direction (p_l = M r^2 / (A cos_p), the density of its
        aperture points).

        Args:
            si: mi.SurfaceInteraction3f (N,) shading points (with their BSDF).
            active: mi.Bool (N,).
            ctx: mi.BSDFContext.
            visibility: function of a lenslet index k (mi.UInt32, (N,)) -> mi.Float (N,), the fraction of lenslet
                k's aperture seen from each shading point.
            lobe_samples: n_b, the BSDF samples the caller adds (0: none).
            seed: varies the aperture points between calls.

        Returns:
            mi.Color3f (N,) radiance.
        """
        mi = mitsuba()
        import drjit as dr

        result = mi.Color3f(0.0)
        n_active = len(self.active_lenslets)
        if n_active == 0:
            return result
        active = mi.Bool(active) & self._on_side(si.p)
        M = self.M
        start = self._start(si, seed + 7)
        n_total = dr.opaque(mi.UInt32, n_active * M)
        bsdf = si.bsdf()
        mis = lobe_samples > 0 and self.model == "area"

        def cond(i, acc):
            return active & (i < n_total)

        def body(i, acc):
            k, m = self._step(i, start)
            p, wn, r2, cos_p, radiance = self._aperture_light(k, m, si.p, active)
            seen = visibility(k)
            lit = active & dr.any(radiance != 0.0) & (seen > 0.0)
            wo = si.to_local(wn)
            f = bsdf.eval(ctx, si, wo, lit)
            g = cos_p * (self.area / M) / r2       # 1 / density of this aperture point, sr
            if mis:
                p_b = bsdf.pdf(ctx, si, wo, lit)
                g = g / (1.0 + lobe_samples * p_b * g)    # times the balance heuristic's weight
            acc += dr.select(lit, f * radiance * (seen * g), 0.0)
            return i + 1, acc

        _, result = dr.while_loop((mi.UInt32(0), result), cond, body)
        return result

    def _aperture_light(self, k, m, x, active):
        """Aperture point m (of the pool; the centre for the point and prefiltered models) of lenslet k and the
        light it sends to points x: (p mi.Point3f, unit direction x -> p, squared distance, cosine at the aperture,
        radiance)."""
        mi = mitsuba()
        import drjit as dr

        p, wn, r2, u, v, cos_p, height = self._aperture_point(k, m, x)
        if self.model == "prefiltered":
            # u = (x - p)_x / x_z, so an aperture of width sqrt(A) spans sqrt(A) / |x_z| in u (and v).
            half = 0.5 * float(np.sqrt(self.area)) / dr.maximum(dr.abs(height), 1e-6)
            radiance = self._box(k, u, v, half, active)
        elif self.reconstruction == "linear":
            base = (k * self.pool + m) * 3
            radiance = mi.Color3f(0.0)
            for t in range(3):
                j = dr.gather(mi.UInt32, self._blend_idx, base + t)
                radiance += dr.gather(mi.Float, self._blend_w, base + t) * self._bilinear(j, u, v, active)
        else:
            radiance = self._bilinear(k, u, v, active)
        return p, wn, r2, cos_p, radiance

    def _aperture_point(self, k, m, x):
        """Aperture point m of lenslet k seen from points x (the lit frame): (p mi.Point3f and the unit direction
        x -> p in the lit frame, squared distance, the (u, v) of the lenslet's direction d = -w (real side) or w
        (synthetic side) there, the cosine at the aperture |d_z|, and x's height over the array plane)."""
        mi = mitsuba()
        import drjit as dr

        sign = -1.0 if self.side == "real" else 1.0  # d = sign * w, w = direction from x to the lenslet
        x = self._point_in(x)
        p = mi.Point3f(dr.gather(mi.Float, self._cx, k) + dr.gather(mi.Float, self._ox, m),
                       dr.gather(mi.Float, self._cy, k) + dr.gather(mi.Float, self._oy, m), 0.0)
        w = p - x
        r2 = dr.squared_norm(w)
        wn = w * dr.rsqrt(r2)
        d = sign * wn
        u = d.x / d.z
        v = d.y / d.z
        return self._point_out(p), self._vector_out(wn), r2, u, v, dr.abs(wn.z), x.z

    # -- the array's frame and the lit frame -----------------------------------------------------------------
    def _point_in(self, p):
        """mi.Point3f in the lit frame -> the array's frame (itself without a pose)."""
        if self.pose is None:
            return p
        t = self.pose[:3, 3]
        return self._vector_in(type(p)(p.x - float(t[0]), p.y - float(t[1]), p.z - float(t[2])))

    def _vector_in(self, w):
        """mi.Vector3f (or Point3f) in the lit frame -> the array's frame: R^T w."""
        if self.pose is None:
            return w
        r = self.pose[:3, :3]
        return type(w)(*(float(r[0, i]) * w.x + float(r[1, i]) * w.y + float(r[2, i]) * w.z for i in range(3)))

    def _vector_out(self, w):
        """The array's frame -> the lit frame: R w."""
        if self.pose is None:
            return w
        r = self.pose[:3, :3]
        return type(w)(*(float(r[i, 0]) * w.x + float(r[i, 1]) * w.y + float(r[i, 2]) * w.z for i in range(3)))

    def _point_out(self, p):
        """The array's frame -> the lit frame: R p + t."""
        if self.pose is None:
            return p
        q, t = self._vector_out(p), self.pose[:3, 3]
        return type(p)(q.x + float(t[0]), q.y + float(t[1]), q.z + float(t[2]))

    def seen_from(self, pose: np.ndarray) -> "LightFieldLight":
        """The same light (its tables shared) lighting points of another frame: ``pose`` (4, 4) takes its array's
        frame there (one interface's projector seen from another interface's frame)."""
        import copy

        other = copy.copy(self)
        other.pose = _rigid(pose)
        return other

    def to_lit_frame(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) points of the array's frame -> the lit frame (float64; themselves without a pose)."""
        points = np.asarray(points, np.float64)
        return points if self.pose is None else rigid_points(self.pose, points)

    def _on_side(self, p):
        """mi.Bool: points of the lit frame on this light's side of the array plane."""
        z = self._point_in(p).z
        return (z > 0) if self.side == "real" else (z < 0)

    def _start(self, si, seed: int):
        """Each shading point's random start in the stratified pool of aperture points (0 where the pool is the M
        points themselves)."""
        mi = mitsuba()
        import drjit as dr

        if self.pool <= self.M:
            return mi.UInt32(0)
        n = dr.width(si.p)
        rng = mi.PCG32(n, dr.opaque(mi.UInt64, self.seed * 1000003 + seed), dr.arange(mi.UInt64, n))
        return rng.next_uint32() % self.pool

    def _step(self, i, start):
        """(lenslet k, aperture point m) of step i of a loop over the active lenslets' M points each."""
        mi = mitsuba()
        import drjit as dr

        M = self.M
        return dr.gather(mi.UInt32, self._active, i // M), (start + i % M + (i // M) * 7919) % self.pool

    # -- texture lookups ---------------------------------------------------------------------------------
    def _bilinear(self, k, u, v, active):
        """Bilinear radiance lookup of lenslet k at (u, v); outside [-a, a]^2 zero (``window="cut"``), or out to
        :data:`EDGE_REACH` a the table extended beyond the window (``"edge"``)."""
        mi = mitsuba()
        import drjit as dr

        inside, taps = self._bilinear_taps(k, u, v, active)
        out = mi.Color3f(0.0)
        for idx, w in taps:
            out += w * self._texel(idx * 3, inside)
        return dr.select(inside, out, 0.0)

    def _bilinear_taps(self, k, u, v, active):
        """Where :meth:`_bilinear` reads: (the points inside the window, its four (texel index, weight) taps)."""
        mi = mitsuba()
        import drjit as dr

        a, m = self.a, self._margin
        fx = (u + a) * (self.U / (2 * a)) - 0.5 + m
        fy = (v + a) * (self.V / (2 * a)) - 0.5 + m
        U, V = self.U + 2 * m, self.V + 2 * m            # the table, extended beyond the window with "edge"
        if self.window == "edge":
            inside = active & (dr.square(u) + dr.square(v) <= (EDGE_REACH * a) ** 2)
        else:
            inside = active & (dr.abs(u) <= a) & (dr.abs(v) <= a)
        fx = dr.clip(fx, 0.0, U - 1.0)
        fy = dr.clip(fy, 0.0, V - 1.0)
        x0 = dr.minimum(mi.UInt32(dr.floor(fx)), U - 2) if U > 1 else mi.UInt32(0)
        y0 = dr.minimum(mi.UInt32(dr.floor(fy)), V - 2) if V > 1 else mi.UInt32(0)
        tx = fx - mi.Float(x0)
        ty = fy - mi.Float(y0)
        base = (k * V + y0) * U + x0
        x1 = 1 if U > 1 else 0
        y1 = U if V > 1 else 0
        return inside, ((base, (1 - tx) * (1 - ty)), (base + x1, tx * (1 - ty)),
                        (base + y1, (1 - tx) * ty), (base + y1 + x1, tx * ty))

    def _texel(self, i, active):
        mi = mitsuba()
        import drjit as dr

        return mi.Color3f(dr.gather(mi.Float, self._table, i, active),
                          dr.gather(mi.Float, self._table, i + 1, active),
                          dr.gather(mi.Float, self._table, i + 2, active))

    def _box(self, k, u, v, half, active):
        """Mean radiance of lenslet k over the (u, v) box of half-width ``half``, from the summed-area table."""
        import drjit as dr

        U, V, a = self.U, self.V, self.a
        if self.window == "edge":    # the box centred at the nearest direction inside the window
            active = active & (dr.square(u) + dr.square(v) <= (EDGE_REACH * a) ** 2)
            u, v = dr.clip(u, -a, a), dr.clip(v, -a, a)
        scale_u, scale_v = U / (2 * a), V / (2 * a)
        # Continuous texel-edge coordinates of the box, clamped to the grid.
        x0 = dr.clip((u - half + a) * scale_u, 0.0, float(U))
        x1 = dr.clip((u + half + a) * scale_u, 0.0, float(U))
        y0 = dr.clip((v - half + a) * scale_v, 0.0, float(V))
        y1 = dr.clip((v + half + a) * scale_v, 0.0, float(V))
        area_px = (2 * half * scale_u) * (2 * half * scale_v)
        total = (self._sat(k, x1, y1, active) - self._sat(k, x0, y1, active)
                 - self._sat(k, x1, y0, active) + self._sat(k, x0, y0, active))
        return dr.select(active & (area_px > 0), total / dr.maximum(area_px, 1e-12), 0.0)

    def _sat(self, k, x, y, active):
        """Summed-area table at continuous (x, y) texel-edge coordinates, bilinear between table nodes."""
        mi = mitsuba()
        import drjit as dr

        U1, V1 = self.U + 1, self.V + 1
        x0 = dr.minimum(mi.UInt32(dr.floor(x)), U1 - 2)
        y0 = dr.minimum(mi.UInt32(dr.floor(y)), V1 - 2)
        tx = x - mi.Float(x0)
        ty = y - mi.Float(y0)
        base = (k * V1 + y0) * U1 + x0
        out = mi.Color3f(0.0)
        for idx, w in ((base, (1 - tx) * (1 - ty)), (base + 1, tx * (1 - ty)),
                       (base + U1, (1 - tx) * ty), (base + U1 + 1, tx * ty)):
            out += w * self._texel(idx * 3, active)
        return out

    # -- shading ----------------------------------------------------------------------------------------
    def illuminate(self, scene, si, active, seed: int = 0, irradiance: Irradiance = False, ctx=None):
        """Light from every lenslet at the points ``si`` (mi.Color3f, (N,)).

        Returns the radiance reflected towards ``-si.wi`` (BSDF-weighted, the components ``ctx`` enables), or
        with ``irradiance`` the (weighted) irradiance on the surface with normal ``si.n``. ``seed`` varies the
        random aperture points (area model with jitter) between calls.
        """
        mi = mitsuba()
        import drjit as dr

        result = mi.Color3f(0.0)
        n_active = len(self.active_lenslets)
        if n_active == 0:
            return result
        # Points on the wrong side of the interface cannot receive light through it.
        active = mi.Bool(active) & self._on_side(si.p)
        n_total = dr.opaque(mi.UInt32, n_active * self.M)
        weight = self.area / self.M
        start = self._start(si, seed)

        def cond(i, acc):
            return i < n_total

        def body(i, acc):
            k, m = self._step(i, start)
            p, wn, r2, cos_p, radiance = self._aperture_light(k, m, si.p, active)
            lit = active & dr.any(radiance != 0.0)
            if irradiance is not False:   # no shadow ray towards lenslets behind the surface
                lit &= dr.dot(si.n, wn) > 0.0
            visible = lit & ~scene.ray_test(si.spawn_ray_to(p), lit)
            f = direction_weight(si, wn, visible, irradiance, ctx)
            acc += dr.select(visible, f * radiance * (cos_p * weight / r2), 0.0)
            return i + 1, acc

        _, result = dr.while_loop((mi.UInt32(0), result), cond, body)
        return result

    # -- the transpose (for inverse problems) ------------------------------------------------------------------
    def _check_linear_table(self, what: str) -> None:
        if self.model == "prefiltered" or self.reconstruction != "box" or self.window != "cut":
            raise ValueError(f"{what} is written for a table read directly (point or area model, box "
                             f"reconstruction, cut window: a projector's lenslets), not model={self.model!r}, "
                             f"reconstruction={self.reconstruction!r}, window={self.window!r}")

    def set_data(self, data: np.ndarray) -> None:
        """Replace the radiance table by ``data`` ((K, V, U, 3) float, W m^-2 sr^-1), keeping the lenslets visited
        and every sample: the light stays the same linear map of its table (what an inverse problem iterates on).

        Raises:
            ValueError: a light whose table is not read directly (:meth:`illuminate_adjoint`), or a wrong shape.
        """
        self._check_linear_table("set_data")
        data = np.asarray(data, np.float32)
        if data.shape != (self.K, self.V, self.U, 3):
            raise ValueError(f"data has shape {data.shape}, expected {(self.K, self.V, self.U, 3)}")
        self._table = jit_array(mitsuba().Float, data.ravel())

    def zero_grad(self) -> None:
        """Start a new transpose: the gradient table (:meth:`grad`) is set to zero."""
        import drjit as dr

        self._grad = dr.zeros(mitsuba().Float, self.K * self.V * self.U * 3)

    def grad(self) -> np.ndarray:
        """(K, V, U, 3) float32: what :meth:`illuminate_adjoint` added since :meth:`zero_grad`."""
        import drjit as dr

        dr.eval(self._grad)
        return np.array(self._grad, dtype=np.float32).reshape(self.K, self.V, self.U, 3)

    def illuminate_adjoint(self, scene, si, active, weight, seed: int = 0) -> None:
        """The transpose of :meth:`illuminate` as a map from the table to the reflected radiance: adds
        sum over points of ``weight`` times d(radiance) / d(table) to the gradient table, with the same aperture
        points, visibility and BSDF values (the same ``seed``), so that for any table T and weights w,
        <w, illuminate(T)> = <grad, T>.

        Args:
            scene, si, active, seed: as in :meth:`illuminate`.
            weight: mi.Color3f (N,), d loss / d (reflected radiance) per point.

        Raises:
            ValueError: a light whose table is not read directly (prefiltered, linear or edge).
        """
        mi = mitsuba()
        import drjit as dr

        self._check_linear_table("illuminate_adjoint")
        if getattr(self, "_grad", None) is None:
            self.zero_grad()
        n_active = len(self.active_lenslets)
        if n_active == 0:
            return
        active = mi.Bool(active) & self._on_side(si.p)
        n_total = dr.opaque(mi.UInt32, n_active * self.M)
        area_weight = self.area / self.M
        start = self._start(si, seed)                  # the same points as illuminate
        grad = self._grad
        weight = mi.Color3f(weight)

        def cond(i):
            return i < n_total

        def body(i):
            k, m = self._step(i, start)
            p, wn, r2, u, v, cos_p, _ = self._aperture_point(k, m, si.p)
            inside, taps = self._bilinear_taps(k, u, v, active)
            visible = inside & ~scene.ray_test(si.spawn_ray_to(p), inside)
            f = direction_weight(si, wn, visible, False, None)
            g = f * weight * (cos_p * area_weight / r2)
            for idx, wt in taps:            # _bilinear's read, transposed: each texel gets its weight times g
                for c in range(3):
                    dr.scatter_add(grad, wt * g[c], idx * 3 + c, visible)
            return (i + 1,)

        dr.while_loop((mi.UInt32(0),), cond, body)

