"""Synthetic lens-array calibration images with known lenslet centres (spot and white images).

The geometry, written out independently of :mod:`lftransfer.calibration.lenslets`:

1. ideal lattice (unit pitch) ``(u, v)`` of index ``(row, col)``: ``u = col + (row % 2) / 2`` (hex) or ``col``
   (rect), ``v = row * sqrt(3) / 2`` (hex) or ``row`` (rect);
2. similarity: scale by ``pitch`` pixels, rotate by ``rotation_deg`` (counter-clockwise on screen, y down), the
   lattice's middle node at ``principal point + shift``;
3. camera tilt: ``x' = x / (1 + a x + b y)`` on coordinates centred on the principal point (a homography);
4. main-lens radial distortion (OpenCV's model): normalised ``n = x' / f`` (``f`` = image width),
   ``n_d = n (1 + k1 |n|^2 + k2 |n|^4)``, pixel ``= principal point + f n_d``. ``k1 > 0``: pincushion,
   ``k1 < 0``: barrel.

Rendering: spots are pixel-integrated Gaussians; white-image sub-images are soft disks or hexagons (flat-to-flat
``aperture * local pitch``) with a soft edge and a radial fall-off inside, supersampled (3 x 3 per pixel by
default); the whole image is multiplied by a ``cos^4``-like vignetting, then photon (Poisson) and read
(Gaussian) noise, a black level, and quantisation to 12 or 16 bits. Sub-images are centrally symmetric about
the true centre, so the true centre is their centre of symmetry (up to the vignetting gradient across each
one).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr

ROW_STEP = {"hex": math.sqrt(3) / 2, "rect": 1.0}


def ideal_coordinates(indices: np.ndarray, lattice: str) -> np.ndarray:
    """Ideal (u, v) of ``(N, 2)`` integer (row, col) indices (unit pitch)."""
    idx = np.asarray(indices)
    r, c = idx[:, 0], idx[:, 1]
    u = c + (0.5 * (r % 2) if lattice == "hex" else 0.0)
    return np.stack([u.astype(np.float64), r * ROW_STEP[lattice]], axis=1)


@dataclass
class LensletImage:
    """A rendered image and its truth.

    Attributes:
        image: ``(H, W) uint16`` codes (``levels`` = full scale).
        levels: full-scale code (4095 for 12 bits, 65535 for 16 bits).
        centres: ``(M, 2)`` true centres (x, y) px of every lenslet whose centre lies in the image.
        indices: ``(M, 2)`` their true (row, col).
        inside: ``(M,) bool``: the spot / sub-image (including its soft edge) lies wholly inside the image.
        lattice, kind: as given.
        radius_px: ``(M,)`` sub-image radius (half the flat-to-flat width, white) or spot sigma (spots), px.
        params: the geometry (for :meth:`to_pixels`).
    """

    image: np.ndarray
    levels: int
    centres: np.ndarray
    indices: np.ndarray
    inside: np.ndarray
    lattice: str
    kind: str
    radius_px: np.ndarray
    params: dict

    def to_pixels(self, uv: np.ndarray) -> np.ndarray:
        """Ideal lattice coordinates -> true pixel positions (the whole geometry)."""
        return _geometry(np.asarray(uv, dtype=np.float64), **self.params)

    def pitch_rotation_at_centre(self) -> tuple[float, float]:
        """Along-row spacing (px) and row direction (deg CCW on screen) of the truth at the image centre."""
        h, w = self.image.shape
        target = np.array([(w - 1) / 2, (h - 1) / 2])
        uv = np.zeros(2)
        for _ in range(50):                                       # Newton on the forward map
            jac = self._jacobian(uv)
            uv = uv - np.linalg.solve(jac, self.to_pixels(uv[None])[0] - target)
        d = self._jacobian(uv)[:, 0]
        return math.hypot(*d), math.degrees(math.atan2(-d[1], d[0]))

    def distortion_shift(self) -> float:
        """Largest displacement by the radial distortion of an in-image lenslet, fraction of the half-diagonal."""
        undistorted = _geometry(ideal_coordinates(self.indices, self.lattice), **dict(self.params, k=(0.0, 0.0)))
        h, w = self.image.shape
        return float(np.max(np.linalg.norm(self.centres - undistorted, axis=1)) / (0.5 * math.hypot(w, h)))

    def _jacobian(self, uv: np.ndarray, eps: float = 1e-5) -> np.ndarray:
        cols = [(self.to_pixels((uv + e)[None])[0] - self.to_pixels((uv - e)[None])[0]) / (2 * eps)
                for e in (np.array([eps, 0.0]), np.array([0.0, eps]))]
        return np.stack(cols, axis=1)


def _geometry(uv, *, lattice_centre, pitch, rotation_deg, tilt, k, pp, f, uv0):
    a = math.radians(rotation_deg)
    rot = np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])   # CCW on screen, y down
    x = (uv - uv0) @ rot.T * pitch + (np.asarray(lattice_centre) - pp)
    x = x / (1.0 + x @ np.asarray(tilt))[:, None]
    n = x / f
    r2 = np.sum(n * n, axis=1, keepdims=True)
    return pp + f * n * (1.0 + k[0] * r2 + k[1] * r2 * r2)


def make_lenslet_image(kind: str = "spots", lattice: str = "hex", *, shape=(800, 1000), pitch: float = 30.0,
                       rotation_deg: float = 2.0, tilt=(2e-5, -1.5e-5), k1: float = -0.06, k2: float = 0.0,
                       pp_offset=(12.0, -8.0), shift=(0.3, 0.6), sigma: float = 1.2, aperture: float = 0.9,
                       shape_kind: str | None = None, edge: float = 0.8, falloff: float = 0.4,
                       inner_falloff: float = 0.3, full_well: float = 5000.0, read_noise: float = 3.0,
                       black: float = 0.01, bits: int = 12, supersample: int = 3, seed: int = 0,
                       jitter: float = 0.0) -> LensletImage:
    """Render a spot or white image of a distorted, tilted, rotated lattice with vignetting and noise.

    Args:
        kind: ``"spots"`` (one Gaussian spot per lenslet) or ``"white"`` (one bright sub-image per lenslet).
        lattice: ``"hex"`` or ``"rect"``.
        shape: ``(H, W)`` pixels.
        pitch: lattice pitch at the principal point, px.
        rotation_deg: lattice rotation, deg counter-clockwise on screen.
        tilt: ``(a, b)`` of the tilt homography, 1/px.
        k1, k2: radial distortion (normalised by f = image width); k1 < 0 barrel, k1 > 0 pincushion.
        pp_offset: principal point minus image centre, px.
        shift: lattice's middle node minus principal point, px.
        sigma: spot sigma, px (spots).
        aperture: sub-image flat-to-flat width / local pitch (white).
        shape_kind: ``"disk"`` or ``"hex"`` sub-images (white); default hex for a hex lattice, disk for rect.
        edge: sigma of the sub-images' soft edge, px.
        falloff: vignetting fall-off at the image corners (0.4: corners at 60 %).
        inner_falloff: relative fall-off from a sub-image's centre to its edge.
        full_well: electrons at full scale (photon noise); read_noise: electrons.
        black: black level, fraction of full scale.
        bits: 12 or 16.
        supersample: white sub-images are rendered with ``supersample x supersample`` samples per pixel.
        seed: noise seed.
        jitter: each spot / sub-image is moved off its lattice node by a random Gaussian offset of this standard
            deviation per axis, in local pitches (drawn from its own generator, seeded by ``seed``): an image
            of blobs that is not a lens array's, with ``centres`` still the lattice nodes (a negative control).
    """
    rng = np.random.default_rng(seed)
    h, w = shape
    f = float(w)
    pp = np.array([(w - 1) / 2 + pp_offset[0], (h - 1) / 2 + pp_offset[1]])
    # enough nodes to cover the image whatever the distortion
    span = int(math.ceil(1.3 * math.hypot(h, w) / pitch)) + 4
    rows = int(span / ROW_STEP[lattice]) | 1
    r, c = np.divmod(np.arange(rows * span), span)
    idx = np.stack([r, c], axis=1)
    uv0 = ideal_coordinates(np.array([[rows // 2, span // 2]]), lattice)[0]
    params = dict(lattice_centre=pp + np.asarray(shift), pitch=pitch, rotation_deg=rotation_deg,
                  tilt=tuple(tilt), k=(k1, k2), pp=pp, f=f, uv0=uv0)
    uv = ideal_coordinates(idx, lattice)
    xy = _geometry(uv, **params)
    if jitter:
        xy = xy + jitter * pitch * np.random.default_rng([seed, 1]).normal(size=xy.shape)
    in_image = (xy[:, 0] >= -0.5) & (xy[:, 0] <= w - 0.5) & (xy[:, 1] >= -0.5) & (xy[:, 1] <= h - 0.5)
    # local scale and rotation of the lattice at each node (finite differences)
    eps = 1e-3
    du = (_geometry(uv + [eps, 0], **params) - _geometry(uv - [eps, 0], **params)) / (2 * eps)
    dv = (_geometry(uv + [0, eps], **params) - _geometry(uv - [0, eps], **params)) / (2 * eps)
    local_pitch = np.sqrt(np.abs(du[:, 0] * dv[:, 1] - du[:, 1] * dv[:, 0]))
    local_angle = np.arctan2(du[:, 1], du[:, 0])
    near = (xy[:, 0] > -pitch) & (xy[:, 0] < w + pitch) & (xy[:, 1] > -pitch) & (xy[:, 1] < h + pitch)
    if kind == "spots":
        img = _render_spots(shape, xy[near], np.full(int(near.sum()), 0.7), sigma)
        radius = np.full(len(xy), sigma)
        reach = 4.0 * sigma
    elif kind == "white":
        shape_kind = shape_kind or ("hex" if lattice == "hex" else "disk")
        radius = 0.5 * aperture * local_pitch
        img = _render_white(shape, xy[near], radius[near], local_angle[near], shape_kind, edge, inner_falloff,
                            ss=supersample)
        reach = radius * (2 / math.sqrt(3) if shape_kind == "hex" else 1.0) + 2 * edge   # hexagon: its corners
        img *= 0.85
    else:
        raise ValueError(kind)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    rr2 = ((xx - pp[0]) ** 2 + (yy - pp[1]) ** 2)
    corner2 = max(np.max((np.array([0, w - 1]) - pp[0]) ** 2) + np.max((np.array([0, h - 1]) - pp[1]) ** 2), 1.0)
    fv2 = corner2 / (1.0 / math.sqrt(1.0 - falloff) - 1.0)       # 1 / (1 + r^2 / fv^2)^2 = 1 - falloff at corner
    img *= 1.0 / (1.0 + rr2 / fv2) ** 2
    electrons = rng.poisson(np.clip(img, 0, None) * full_well).astype(np.float64)
    electrons += rng.normal(0.0, read_noise, img.shape)
    levels = (1 << bits) - 1
    codes = np.round(np.clip(electrons / full_well + black, 0.0, 1.0) * levels).astype(np.uint16)
    inset = np.minimum(np.minimum(xy[:, 0], w - 1 - xy[:, 0]), np.minimum(xy[:, 1], h - 1 - xy[:, 1]))
    inside = inset >= reach
    return LensletImage(image=codes, levels=levels, centres=xy[in_image], indices=idx[in_image],
                        inside=inside[in_image], lattice=lattice, kind=kind, radius_px=radius[in_image],
                        params=params)


def _scatter(shape, rows, cols, values):
    """Add ``values`` at integer pixel positions (any shape, same for all three), clipped to the image."""
    h, w = shape
    ok = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
    flat = rows[ok] * w + cols[ok]
    return np.bincount(flat, weights=values[ok], minlength=h * w).reshape(h, w)


def _render_spots(shape, xy, amp, sigma):
    """Pixel-integrated Gaussian spots of peak ``amp`` (separable per spot, scattered patches)."""
    half = int(math.ceil(5 * sigma)) + 1
    off = np.arange(-half, half + 1)
    base = np.rint(xy).astype(np.int64)
    px = base[:, :1] + off[None]                                 # (N, P) columns
    py = base[:, 1:] + off[None]                                 # (N, P) rows
    gx = ndtr((px + 0.5 - xy[:, :1]) / sigma) - ndtr((px - 0.5 - xy[:, :1]) / sigma)
    gy = ndtr((py + 0.5 - xy[:, 1:]) / sigma) - ndtr((py - 0.5 - xy[:, 1:]) / sigma)
    norm = (ndtr(0.5 / sigma) - ndtr(-0.5 / sigma)) ** 2
    vals = gy[:, :, None] * gx[:, None, :] * (amp / norm)[:, None, None]
    rows = np.broadcast_to(py[:, :, None], vals.shape)
    cols = np.broadcast_to(px[:, None, :], vals.shape)
    return _scatter(shape, rows, cols, vals)


def _render_white(shape, xy, radius, angle, shape_kind, edge, inner_falloff, ss=3, chunk=512):
    """Soft disks / hexagons (flat-to-flat ``2 radius``), supersampled ``ss x ss`` per pixel; light adds.

    The edge is a smoothstep from ``radius + 2 edge`` (0) to ``radius - 2 edge`` (1) of the distance to the
    centre (disk) or of the largest distance along the three side normals (hexagon, sides facing the
    neighbours); inside, ``1 - inner_falloff (r / radius)^2``.
    """
    img = np.zeros(shape)
    reach = radius.max() * (2 / math.sqrt(3) if shape_kind == "hex" else 1.0) + 2 * edge
    half = int(math.ceil(reach)) + 1
    off = np.arange(-half, half + 1)
    sub = (np.arange(ss) + 0.5) / ss - 0.5
    so = (off[:, None] + sub[None]).ravel().astype(np.float32)   # (P * ss,) sample offsets
    p = len(off)
    for s in range(0, len(xy), chunk):
        c = xy[s:s + chunk]
        n = len(c)
        base = np.rint(c).astype(np.int64)
        dx = ((base[:, :1] - c[:, :1]).astype(np.float32) + so[None])[:, None, :]      # (n, 1, P*ss)
        dy = ((base[:, 1:] - c[:, 1:]).astype(np.float32) + so[None])[:, :, None]      # (n, P*ss, 1)
        rad = radius[s:s + chunk, None, None].astype(np.float32)
        rr2 = dx * dx + dy * dy
        if shape_kind == "hex":                                   # sides normal to 0, 60 and 120 deg
            a = angle[s:s + chunk, None, None]
            p1 = dx * np.cos(a).astype(np.float32) + dy * np.sin(a).astype(np.float32)
            p2 = dx * np.cos(a + math.pi / 3).astype(np.float32) + dy * np.sin(a + math.pi / 3).astype(np.float32)
            d = np.maximum(np.maximum(np.abs(p1), np.abs(p2)), np.abs(p2 - p1))   # cos(x + 120) = cos(x + 60) - cos x
        else:
            d = np.sqrt(rr2)
        t = np.clip((rad + 2 * edge - d) / np.float32(4 * edge), 0, 1)
        val = t * t * (3 - 2 * t) * np.clip(1 - inner_falloff * rr2 / (rad * rad), 0, 1)
        val = val.reshape(n, p, ss, p, ss).sum(axis=4).sum(axis=2).astype(np.float64) / (ss * ss)
        rows = np.broadcast_to((base[:, 1:] + off[None])[:, :, None], val.shape)
        cols = np.broadcast_to((base[:, :1] + off[None])[:, None, :], val.shape)
        img += _scatter(shape, rows, cols, val)
    return img
