"""The lattice through the detections (step 3 of :mod:`lftransfer.calibration.lenslets`): indices and the model fit.

Pitch and rotation from the nearest neighbours, integer indices grown from the middle outwards through local
lattice Jacobians, then the lattice model (:mod:`.model`) fitted to them with outliers dropped, the
detections the growth did not reach assigned through the model, and the result as a :class:`LatticeFit`.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from lftransfer.calibration.lenslets.common import (_ROW_STEP, _SQRT3_2, NoSpotsError, _check_shape,
                                                    lattice_coordinates)
from lftransfer.calibration.lenslets.fit import LatticeFit
from lftransfer.calibration.lenslets.model import (_fit_model, _Model, _model_apply, _model_inverse,
                                                   _pitch_rotation)

_MAX_RESIDUAL = 0.25       # a detection farther than this (lattice pitches) from its node is not a lenslet
_OUTLIER_SIGMAS = 8.0      # a detection farther than this many robust sigmas off the lattice model is dropped
_OUTLIER_FLOOR_PX = 0.2    # ... if also farther than this (pixels)
_GROW_REACH = 2.2          # growth: detections this close (pitches) to assigned ones are predicted from them
_GROW_TOL = 0.3            # ... and take the nearest node if their mean prediction is this close (pitches)
_GROW_AGREE = 0.4          # ... and every single neighbour's prediction this close
_JAC_REACH = 2.6           # local lattice Jacobian: affine fit of the assigned nodes within this (pitches)


def _nearest_nodes(uv: np.ndarray, lattice: str) -> tuple[np.ndarray, np.ndarray]:
    """Nearest lattice nodes of ideal coordinates: ``(N, 2) int64`` (row, col) and their ``(N, 2)`` (u, v)."""
    r = np.rint(uv[:, 1] / _ROW_STEP[lattice]).astype(np.int64)
    shift = 0.5 * (r % 2) if lattice == "hex" else 0.0
    c = np.rint(uv[:, 0] - shift).astype(np.int64)
    idx = np.stack([r, c], axis=1)
    return idx, lattice_coordinates(idx, lattice)


def _keys(idx: np.ndarray) -> np.ndarray:
    """One int64 per (row, col) index pair."""
    return (idx[:, 0] + (1 << 24)) * (1 << 26) + (idx[:, 1] + (1 << 24))


def _closest_per_node(idx: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """``(N,) bool``: True on the closest of the detections that share a node."""
    order = np.lexsort((dist, idx[:, 1], idx[:, 0]))
    first = np.ones(len(order), bool)
    first[1:] = np.any(idx[order][1:] != idx[order][:-1], axis=1)
    unique = np.zeros(len(idx), bool)
    unique[order[first]] = True
    return unique


def _local_jacobians(points: np.ndarray, uv: np.ndarray, done: np.ndarray, which: np.ndarray, pitch: float
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Local lattice Jacobians ``d(x, y) / d(u, v)`` at detections ``which`` from the assigned ones near them.

    Affine least-squares fit of the assigned detections within ``_JAC_REACH`` pitches (up to 13).

    Returns:
        ``(M, 2, 2)`` Jacobians and ``(M,) bool``: the fit was well posed (at least 4 nodes spanning two
        directions); where not, the Jacobian is left zero.
    """
    a = np.flatnonzero(done)
    k = min(13, len(a))
    d, j = cKDTree(points[a]).query(points[which], k=k, distance_upper_bound=_JAC_REACH * pitch)
    d, j = d.reshape(len(which), k), j.reshape(len(which), k)
    valid = np.isfinite(d).astype(np.float64)
    nb = a[np.minimum(j, len(a) - 1)]
    duv = (uv[nb] - uv[which][:, None, :]) * valid[..., None]
    dxy = (points[nb] - points[which][:, None, :]) * valid[..., None]
    x = np.concatenate([duv, valid[..., None]], axis=2)          # (M, k, 3): [du, dv, 1]
    a_mat = np.einsum("mki,mkj->mij", x, x)
    rhs = np.einsum("mki,mkj->mij", x, dxy)                      # (M, 3, 2)
    cnt = np.maximum(a_mat[:, 2, 2], 1.0)
    cov = a_mat[:, :2, :2] - np.einsum("mi,mj->mij", a_mat[:, :2, 2], a_mat[:, :2, 2]) / cnt[:, None, None]
    fine = (valid.sum(axis=1) >= 4) & (np.linalg.eigvalsh(cov)[:, 0] > 0.5)
    jac = np.zeros((len(which), 2, 2))
    if fine.any():
        sol = np.linalg.solve(a_mat[fine], rhs[fine])            # (m, 3, 2): rows du, dv, 1
        jac[fine] = np.transpose(sol[:, :2, :], (0, 2, 1))
    return jac, fine


def _grow(points: np.ndarray, lattice: str, ref: int, jac0: np.ndarray, pitch: float
          ) -> tuple[np.ndarray, np.ndarray]:
    """Lattice indices grown from detection ``ref`` (index (0, 0)) outwards (see the module's docstring).

    Args:
        points: ``(N, 2)`` detections, pixels.
        lattice: ``"hex"`` or ``"rect"``.
        ref: the starting detection.
        jac0: ``(2, 2)`` lattice Jacobian ``d(x, y) / d(u, v)`` at ``ref``.
        pitch: typical neighbour distance, pixels.

    Returns:
        ``(N,) bool`` assigned and ``(N, 2) int64`` indices relative to ``ref`` (meaningless where unassigned).
    """
    n = len(points)
    done = np.zeros(n, bool)
    idx = np.zeros((n, 2), np.int64)
    uv = np.zeros((n, 2))
    jac = np.zeros((n, 2, 2))
    done[ref] = True
    jac[ref] = jac0
    taken = _keys(idx[[ref]])
    while True:
        a = np.flatnonzero(done)
        u = np.flatnonzero(~done)
        if not len(u):
            break
        k = min(4, len(a))
        d, j = cKDTree(points[a]).query(points[u], k=k, distance_upper_bound=_GROW_REACH * pitch)
        d, j = d.reshape(len(u), k), j.reshape(len(u), k)
        valid = np.isfinite(d)
        near = valid[:, 0]
        if not near.any():
            break
        u, d, j, valid = u[near], d[near], j[near], valid[near]
        nb = a[np.minimum(j, len(a) - 1)]                        # (M, k)
        delta = points[u][:, None, :] - points[nb]
        pred = uv[nb] + np.linalg.solve(jac[nb], delta[..., None])[..., 0]
        wts = valid / np.maximum(d, 1e-9)
        mean = np.einsum("mk,mki->mi", wts, pred) / wts.sum(axis=1)[:, None]
        nid, nuv = _nearest_nodes(mean, lattice)
        dist = np.linalg.norm(mean - nuv, axis=1)
        agree = np.all(~valid | (np.linalg.norm(pred - nuv[:, None, :], axis=2) < _GROW_AGREE), axis=1)
        good = (dist < _GROW_TOL) & agree & ~np.isin(_keys(nid), taken)
        if not good.any():
            break
        u, nid, nuv, dist, nb = u[good], nid[good], nuv[good], dist[good], nb[good]
        first = _closest_per_node(nid, dist)
        u, nid, nuv, nb = u[first], nid[first], nuv[first], nb[first]
        done[u] = True
        idx[u] = nid
        uv[u] = nuv
        taken = np.concatenate([taken, _keys(nid)])
        local, fine = _local_jacobians(points, uv, done, u, pitch)
        jac[u] = np.where(fine[:, None, None], local, jac[nb[:, 0]])  # else: the nearest neighbour's
    return done, idx


def _assign_model(model: _Model, points: np.ndarray, lattice: str, tol: float, taken: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Nodes of ``points`` through the inverse lattice model: one per free node (the closest), within ``tol``.

    Returns:
        ``(N,) bool`` assigned and ``(N, 2) int64`` indices.
    """
    uv = _model_inverse(model, points)
    idx, nodes = _nearest_nodes(uv, lattice)
    dist = np.linalg.norm(uv - nodes, axis=1)
    ok = np.isfinite(dist) & (dist < tol) & ~np.isin(_keys(idx), taken)
    return ok & _closest_per_node(idx, np.where(ok, dist, np.inf)), idx


def _final_indices(idx_rel: np.ndarray, lattice: str, row_offset: int) -> np.ndarray:
    """Indices relative to the reference spot -> top detected row ``row_offset``, leftmost column 0."""
    r_rel, c_rel = idx_rel[:, 0], idx_rel[:, 1]
    r = r_rel - r_rel.min() + row_offset
    if lattice == "hex":
        u2 = 2 * c_rel + (r_rel % 2)                         # twice the ideal u, integer
        c2 = u2 - (r % 2)                                    # twice (u - (r % 2) / 2): all even or all odd
        c = (c2 - c2.min()) // 2
    else:
        c = c_rel - c_rel.min()
    return np.stack([r, c], axis=1).astype(np.int64)


def _clean_fit(points: np.ndarray, idx_rel: np.ndarray, ok: np.ndarray, lattice: str, shape: tuple[int, int],
               what: str = "spots") -> tuple[_Model, float]:
    """Fit the lattice model to ``points[ok]``, drop outliers from ``ok`` (in place), refit until none is dropped.

    An outlier lies a quarter pitch or more off its node, or farther from its fitted position than
    ``_OUTLIER_SIGMAS`` robust sigmas of the residuals (``median length / 1.1774``, a 2-D Gaussian's) and
    ``_OUTLIER_FLOOR_PX``: a detection disturbed by something (a sub-image cut by the edge of the lit area, a
    hot pixel on a spot) is dropped rather than bending the lattice.

    Returns:
        The last model and the residual length (pixels) beyond which a detection is an outlier.
    """
    n = len(points)
    for _ in range(10):
        uv_nodes = lattice_coordinates(idx_rel[ok], lattice)
        model, _, _ = _fit_model(uv_nodes, points[ok], shape)
        off = np.linalg.norm(_model_inverse(model, points[ok]) - uv_nodes, axis=1)    # pitches
        res = np.linalg.norm(points[ok] - _model_apply(model, uv_nodes), axis=1)     # pixels
        limit = max(_OUTLIER_SIGMAS * float(np.median(res)) / 1.1774, _OUTLIER_FLOOR_PX)
        bad = (off >= _MAX_RESIDUAL) | (res > limit)
        if not bad.any():
            break
        ok[np.flatnonzero(ok)[bad]] = False
        if ok.sum() < 4:
            raise NoSpotsError(f"only {int(ok.sum())} of {n} {what} fit a {lattice} lattice; "
                               "at least 4 are needed")
    return model, limit


def _indices(idx_rel: np.ndarray, lattice: str, expected_shape: tuple[int, int] | None, what: str):
    """The nodes' final (row, column) indices, and the expected array shape checked: a hex lattice whose top
    detected row is an odd row is shifted to fit it.

    Raises:
        NoSpotsError: the nodes span more rows or columns than the expected array.
    """
    indices = _final_indices(idx_rel, lattice, 0)
    if expected_shape is None:
        return indices, None
    rows_e, cols_e = _check_shape(expected_shape)
    span = indices.max(axis=0) + 1
    if lattice == "hex" and span[1] > cols_e and span[0] < rows_e:
        shifted = _final_indices(idx_rel, lattice, 1)             # the top detected row is an odd row
        if np.all(shifted.max(axis=0) + 1 <= (rows_e, cols_e)):
            indices = shifted
    span = indices.max(axis=0) + 1
    if span[0] > rows_e or span[1] > cols_e:
        raise NoSpotsError(f"the {what} span {span[0]} rows x {span[1]} columns, more than the expected "
                           f"{rows_e} x {cols_e} array")
    return indices, (rows_e, cols_e)


def _fit_lattice(points: np.ndarray, lattice: str, shape: tuple[int, int], sigma: float,
                 expected_shape: tuple[int, int] | None, kind: str = "spots") -> LatticeFit:
    n = len(points)
    what = "spots" if kind == "spots" else "sub-images"
    tree = cKDTree(points)
    d, j = tree.query(points, k=min(7, n))
    pitch0 = float(np.median(d[:, 1]))
    if not pitch0 > 0:
        raise NoSpotsError(f"the {n} {what} do not form a lattice (coincident detections)")
    near = (d[:, 1:] > 0.7 * pitch0) & (d[:, 1:] < 1.3 * pitch0)
    vec = (points[j[:, 1:]] - points[:, None, :])[near]
    fold = 6 if lattice == "hex" else 4
    z = np.mean(np.exp(1j * fold * np.arctan2(vec[:, 1], vec[:, 0]))) if len(vec) else 0.0
    if abs(z) < 0.5:
        raise NoSpotsError(f"the {n} {what} do not form a {lattice} lattice (neighbour directions disagree with "
                           f"a {360 // fold}-degree symmetry)")
    theta = np.angle(z) / fold
    b_angle = theta + (math.pi / 3 if lattice == "hex" else math.pi / 2)
    basis = pitch0 * np.array([[math.cos(theta), math.cos(b_angle)], [math.sin(theta), math.sin(b_angle)]])
    # Reference: the spot nearest the middle of the detections among those with the most lattice neighbours
    # (not a stray detection).
    degree = near.sum(axis=1)
    well = np.flatnonzero(degree >= min(3, degree.max()))
    centre = np.median(points, axis=0)
    ref_i = int(well[np.argmin(np.linalg.norm(points[well] - centre, axis=1))])
    ref = points[ref_i]
    # Refine the two lattice vectors near the reference spot.
    local = np.linalg.norm(points - ref, axis=1) < 4.0 * pitch0
    lvec = (points[j[:, 1:]] - points[:, None, :])[near & local[:, None]]
    for col in range(2):
        e = basis[:, col]
        close = np.minimum(np.linalg.norm(lvec - e, axis=1), np.linalg.norm(lvec + e, axis=1)) < 0.3 * pitch0
        if close.any():
            v = lvec[close]
            v = np.where((v @ e)[:, None] < 0, -v, v)
            basis[:, col] = v.mean(axis=0)
    ideal_basis = np.array([[1.0, 0.5], [0.0, _SQRT3_2]]) if lattice == "hex" else np.eye(2)
    jac0 = basis @ np.linalg.inv(ideal_basis)
    if abs(np.linalg.det(jac0)) < 1e-9 * pitch0 * pitch0:
        raise NoSpotsError(f"the {n} {what} do not form a {lattice} lattice (degenerate lattice vectors)")
    # Indices: grow the lattice from the reference outwards, each node predicted by its assigned neighbours.
    ok, idx_rel = _grow(points, lattice, ref_i, jac0, pitch0)
    if ok.sum() < 4:
        raise NoSpotsError(f"only {int(ok.sum())} of {n} {what} fit a {lattice} lattice; at least 4 are needed")
    # Lattice model through the grown nodes, without the detections off it; then the detections the growth
    # did not reach (beyond gaps) through the model, and the model again.
    model, limit = _clean_fit(points, idx_rel, ok, lattice, shape, what)
    rest = np.flatnonzero(~ok)
    if len(rest):
        more, idx_more = _assign_model(model, points[rest], lattice, _MAX_RESIDUAL, _keys(idx_rel[ok]))
        more &= np.linalg.norm(points[rest] - _model_apply(model, lattice_coordinates(idx_more, lattice)),
                               axis=1) <= limit
        ok[rest[more]] = True
        idx_rel[rest[more]] = idx_more[more]
        if more.any():
            _clean_fit(points, idx_rel, ok, lattice, shape, what)
    kept, idx_rel = points[ok], idx_rel[ok]
    indices, expected_shape = _indices(idx_rel, lattice, expected_shape, what)
    order = np.lexsort((indices[:, 1], indices[:, 0]))
    kept, indices = kept[order], indices[order]
    ideal = lattice_coordinates(indices, lattice)
    model, rms, rms_h = _fit_model(ideal, kept, shape)
    residuals = kept - _model_apply(model, ideal)
    rms = float(np.sqrt(np.mean(np.sum(residuals ** 2, axis=1))))
    pitch, rotation = _pitch_rotation(model, shape)
    return LatticeFit(lattice=lattice, centres=kept, indices=indices, homography=model.h, residuals=residuals,
                      rms_px=rms, pitch_px=pitch, rotation_deg=rotation,
                      origin=_model_apply(model, np.zeros((1, 2)))[0], image_shape=(int(shape[0]), int(shape[1])),
                      spot_sigma_px=float(sigma), rejected=int(n - len(kept)), expected_shape=expected_shape,
                      distortion=model.k, distortion_centre=model.centre, distortion_scale=model.scale,
                      homography_rms_px=rms if not np.any(model.k) else float(rms_h), kind=kind)
