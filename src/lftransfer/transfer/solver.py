"""Box-constrained linear least squares: min ||A x - b||^2 over 0 <= x <= upper, for A given as a map and its exact
transpose (MFISTA). The projector's drive is solved with it twice: against the measured real surface by the
transfer (:mod:`lftransfer.transfer.surface_solve`) and against the true real objects by the fidelity floor
(:mod:`lftransfer.sim.floor`), so the method and its yardstick share one solver.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Callable

import numpy as np

__all__ = ["BoxFit", "FLOOR_ITERATIONS", "POWER_ITERATIONS", "RowBlocks", "box_least_squares"]

FLOOR_ITERATIONS = 40          # MFISTA steps of the fidelity floor, at most
POWER_ITERATIONS = 6           # for the step size (largest eigenvalue of A^T A)


MAX_THREADS = 4                # row blocks of a RowBlocks product, at most


@lru_cache(maxsize=1)
def _pool(threads: int) -> ThreadPoolExecutor:
    return ThreadPoolExecutor(max_workers=threads, thread_name_prefix="lft-sparse")


class RowBlocks:
    """A sparse matrix's product with a dense one, its rows split into blocks multiplied at once on a thread pool
    (SciPy's sparse product releases the GIL: on 2 cores a product of 4.4 M nonzeros by 3 columns takes 8 ms
    instead of 14).

    Args:
        matrix: a ``scipy.sparse`` matrix (made CSR).
        threads: blocks (default: the cores this process may use, at most :data:`MAX_THREADS`).
    """

    def __init__(self, matrix, threads: int | None = None) -> None:
        matrix = matrix.tocsr()
        self.shape = matrix.shape
        n = threads or min(MAX_THREADS, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
                           else (os.cpu_count() or 1))
        n = max(1, min(int(n), matrix.shape[0]))
        # blocks of equal nonzeros rather than equal rows
        cuts = np.searchsorted(matrix.indptr, np.linspace(0, matrix.nnz, n + 1)).clip(0, matrix.shape[0])
        cuts[0], cuts[-1] = 0, matrix.shape[0]
        self._blocks = [matrix[a:b] for a, b in zip(cuts[:-1], cuts[1:]) if b > a]

    def __matmul__(self, x: np.ndarray) -> np.ndarray:
        """The product with ``x``: (columns,) or (columns, C). Each of C > 1 columns is multiplied on its own:
        SciPy's product with several columns at once runs a slow inner loop per nonzero (a solve's 4.8 M nonzeros
        by 3 columns: 18 ms, against 13 ms for the three columns apart, on one core), and adds the same terms in
        the same order, so the result is the same to the bit."""
        x = np.asarray(x)
        if x.ndim == 2 and x.shape[1] > 1:
            columns = [np.ascontiguousarray(x[:, c]) for c in range(x.shape[1])]

            def product(block):
                return np.stack([np.asarray(block @ column) for column in columns], axis=1)
        else:
            def product(block):
                return np.asarray(block @ x)
        if len(self._blocks) == 1:
            return product(self._blocks[0])
        return np.concatenate(list(_pool(len(self._blocks)).map(product, self._blocks)))


@dataclass(frozen=True)
class BoxFit:
    """What :func:`box_least_squares` found.

    Attributes:
        x: the best point found, the shape of ``start``.
        losses: ||A x - b||^2 of the start and after each step (the best so far: never increasing).
        lipschitz: the largest eigenvalue of A^T A found by power iteration (the step is 1 / (1.05 of it)).
        snapshots: step -> the best point after that many steps, for the steps asked for (``keep``).
    """

    x: np.ndarray
    losses: list[float]
    lipschitz: float
    snapshots: dict[int, np.ndarray] = field(default_factory=dict)


def box_least_squares(apply: Callable[[np.ndarray], np.ndarray], transpose: Callable[[np.ndarray], np.ndarray],
                      target: np.ndarray, start: np.ndarray, upper: np.ndarray, *,
                      iterations: int = FLOOR_ITERATIONS, power_iterations: int = POWER_ITERATIONS,
                      keep: tuple[int, ...] = (), progress: Callable[[str], None] | None = None,
                      lipschitz: float | None = None, monotone: bool = True, tolerance: float = 0.0) -> BoxFit:
    """min ||A x - b||^2 over 0 <= x <= upper by MFISTA (projected gradient with Nesterov momentum, each step kept
    only where it lowers the loss, so the result is never worse than ``start``; Beck and Teboulle 2009).

    Args:
        apply: x -> A x; transpose: r -> A^T r (exact transposes of each other).
        target: b, the shape of A x.
        start: a feasible x.
        upper: the upper bound of each x (>= 0).
        iterations: steps (3 applications of A or A^T each).
        power_iterations: power-iteration steps for the step size (2 applications each).
        keep: steps after which to keep the best point so far (``BoxFit.snapshots``).
        progress: called every 10 steps.
        lipschitz: the largest eigenvalue of A^T A where known (an earlier fit's ``BoxFit.lipschitz`` for the same
            A): no power iteration then.
        monotone: MFISTA (each step's loss evaluated, the best point kept: 3 applications a step) or, False, FISTA
            with the gradient restart of O'Donoghue and Candes 2015 (momentum reset where it points uphill: 2
            applications a step; the step from the best of the points the steps start from is returned, and
            it lowers the loss, so the result is still never worse than ``start``). ``losses`` then bound the
            result's loss from above: the best loss of the points the steps started from.
        tolerance: (``monotone=False`` only) stop once a step's guaranteed decrease, L |z - y|^2 / 2 for the
            projected gradient step from y to z, is below this fraction of the loss at y: the point is converged
            to that precision (a warm start at the last solution stops after its first step).
    """
    rng = np.random.default_rng(0)
    v = rng.random(start.shape).astype(np.float32) * upper
    known = lipschitz
    lipschitz = 0.0 if known is None else float(known)
    for _ in range(power_iterations if known is None else 0):
        av = transpose(apply(v))
        lipschitz = float(np.sqrt(np.sum(av.astype(np.float64) ** 2) / max(np.sum(v.astype(np.float64) ** 2),
                                                                            1e-300)))
        v = av / max(float(np.abs(av).max()), 1e-30)
    step = np.float32(1.0 / (1.05 * lipschitz)) if lipschitz > 0 else np.float32(0.0)

    def loss(x: np.ndarray) -> tuple[float, np.ndarray]:
        r = apply(x) - target
        return float(np.sum(r.astype(np.float64) ** 2)), r

    if not monotone:
        return _restarted(apply, transpose, target, start, upper, iterations, lipschitz, step, tolerance)
    x = np.clip(start, 0.0, upper).astype(np.float32)
    best_loss, r_y = loss(x)
    losses = [best_loss]
    best, y, tk = x, x, 1.0
    snapshots: dict[int, np.ndarray] = {}
    for k in range(iterations):
        z = np.clip(y - step * transpose(r_y), 0.0, upper)
        z_loss, _ = loss(z)
        if z_loss < best_loss:
            best, best_loss = z, z_loss
        losses.append(best_loss)
        t_next = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * tk * tk))
        y = np.clip(best + np.float32(tk / t_next) * (z - best) + np.float32((tk - 1.0) / t_next) * (best - x),
                    0.0, upper)
        x, tk = best, t_next
        if k + 1 in keep:
            snapshots[k + 1] = best
        if k + 1 < iterations:
            r_y = apply(y) - target
        if progress and (k + 1) % 10 == 0:
            progress(f"step {k + 1}/{iterations}, loss {best_loss / max(losses[0], 1e-300):.3g} of the start's")
    return BoxFit(x=best, losses=losses, lipschitz=lipschitz, snapshots=snapshots)


def _restarted(apply, transpose, target, start, upper, iterations, lipschitz, step, tolerance) -> BoxFit:
    """FISTA with gradient restart (``box_least_squares(monotone=False)``): 2 applications a step, none more. The
    loss is known at each step's extrapolated point y_k; a projected gradient step of length 1 / L from y_k lowers
    it (the descent lemma), so the step taken from the best y_k is returned: never worse than ``start`` (y_0)."""
    x = np.clip(start, 0.0, upper).astype(np.float32)
    y, tk = x, 1.0
    losses: list[float] = []
    best, best_loss = x, np.inf
    for _ in range(iterations):
        r = apply(y) - target
        y_loss = float(np.sum(r.astype(np.float64) ** 2))
        z = np.clip(y - step * transpose(r), 0.0, upper)
        if y_loss <= best_loss:
            best, best_loss = z, y_loss
        losses.append(min(best_loss, losses[-1]) if losses else y_loss)
        if 0.5 * lipschitz * float(np.sum((z - y).astype(np.float64) ** 2)) < tolerance * y_loss:
            break
        if float(np.vdot(y - z, z - x)) > 0.0:          # the momentum points uphill: restart it
            tk = 1.0
        t_next = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * tk * tk))
        y = np.clip(z + np.float32((tk - 1.0) / t_next) * (z - x), 0.0, upper)
        x, tk = z, t_next
    return BoxFit(x=best, losses=losses, lipschitz=lipschitz)
