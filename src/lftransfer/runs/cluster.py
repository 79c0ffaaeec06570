"""Work spread over a Ray cluster: the frames of a converged sequence, their ground truths, calibrations over
seeds and the cells of a study (``--cluster auto|local|ray://HOST:PORT``; docs/architecture.md, "Scale-out").

Ray (the optional extra ``lftransfer[cluster]``) is the engine: its scheduler, its object store, its retries.
What this module adds is what light field transfer needs of it:

- **warm workers**: each worker is a Ray actor, one process that sets the Mitsuba variant once, compiles its
  kernels on its first task and keeps them, and keeps its simulated rig open between tasks. Ray starts actor
  processes afresh from the Python interpreter (never a fork of the driver, which Dr.Jit does not survive).
  Where the cluster has GPUs there is one worker per GPU (``cuda_ad_rgb``); otherwise one per CPU core (or as
  many as asked for, each with its share of the cores as Dr.Jit threads);
- **retries**: a worker that dies (killed, out of memory, a lost node) is restarted by Ray and its task is run
  again; the caller never sees it unless it keeps dying;
- **results as they finish**: :meth:`WorkerPool.map` yields each result as soon as it arrives, so the caller
  writes it at once and an interrupted job resumes without redoing finished work.

Results do not depend on which worker ran a task or in which order: every random number of a frame is drawn from
the frame's index and the sample indices (:meth:`lftransfer.runs.rigs.OpenedRig.start_frame`), so a sequence
rendered on a cluster is bit-identical to the same sequence rendered in one process.
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Iterable, Iterator, Sequence

__all__ = ["ClusterError", "ClusterInfo", "ClusterSpec", "LocalPool", "Worker", "WorkerPool", "connect"]

# Environment variables the workers must see as the driver does (the LLVM library, the variant, the caches).
_FORWARDED_ENV = ("DRJIT_LIBLLVM_PATH", "LFT_VARIANT", "LFT_CACHE_DIR", "DRJIT_CACHE_DIR")
MIN_THREADS = 2                 # Dr.Jit threads per worker, at least (see WorkerPool)
MAX_RETRIES = 3                 # restarts of a dead worker, and reruns of the task it was running


class ClusterError(RuntimeError):
    """The cluster cannot be reached or used; the message says which and what to do."""


@dataclass(frozen=True)
class ClusterSpec:
    """Where work runs.

    Attributes:
        kind: ``"auto"`` (the cluster this machine belongs to, if ``ray start`` made one, else a local one),
            ``"local"`` (a Ray cluster started on this machine for this job and stopped after it) or ``"ray"``
            (a running cluster at ``address``).
        address: ``ray://HOST:PORT`` of a running cluster (kind ``"ray"``).
        workers: number of workers (None: one per GPU, else one per CPU core of the cluster).
    """

    kind: str = "auto"
    address: str | None = None
    workers: int | None = None

    @classmethod
    def parse(cls, text: str, workers: int | None = None) -> "ClusterSpec":
        """``"auto"``, ``"local"`` or ``"ray://HOST:PORT"`` -> ClusterSpec (ValueError naming what is wrong)."""
        text = str(text).strip()
        if workers is not None and not (isinstance(workers, int) and workers >= 1):
            raise ValueError(f"--workers: expected an integer >= 1, got {workers!r}")
        if text in ("auto", "local"):
            return cls(text, None, workers)
        if text.startswith("ray://"):
            host, _, port = text[len("ray://"):].rpartition(":")
            if host and port.isdigit() and 0 < int(port) < 65536:
                return cls("ray", text, workers)
        raise ValueError(f"--cluster {text!r}: expected 'auto', 'local' or 'ray://HOST:PORT'")

    def __str__(self) -> str:
        return self.address if self.kind == "ray" else self.kind


@dataclass(frozen=True)
class ClusterInfo:
    """The cluster a job runs on.

    Attributes:
        address: where it is (``"local"`` for one started here).
        cpus: CPU cores it has.
        gpus: GPUs it has.
        started_here: the job started it (and stops it at the end).
    """

    address: str
    cpus: float
    gpus: float
    started_here: bool

    def default_workers(self) -> int:
        """One worker per GPU, else one per CPU core."""
        return int(self.gpus) if self.gpus >= 1 else max(1, int(self.cpus))


def _ray():
    try:
        import ray
    except ImportError:
        raise ClusterError("--cluster needs Ray: pip install 'lftransfer[cluster]'") from None
    return ray


@contextmanager
def connect(spec: ClusterSpec) -> Iterator[ClusterInfo]:
    """Connect to the cluster ``spec`` names (starting a local one where it says so) for the ``with`` block.

    Raises:
        ClusterError: Ray is not installed, or the cluster at the address cannot be reached.
    """
    ray = _ray()
    env = {k: os.environ[k] for k in _FORWARDED_ENV if k in os.environ}
    runtime_env = {"env_vars": env} if env else None
    common = {"include_dashboard": False, "log_to_driver": True, "configure_logging": False,
              "runtime_env": runtime_env}
    if ray.is_initialized():                      # a caller (a test, a notebook) connected already
        yield _info(ray, "connected", False)
        return
    address, started = spec.address, False
    if spec.kind == "auto":
        try:
            ray.init(address="auto", **common)
            address = "auto"
        except (ConnectionError, RuntimeError):
            spec = ClusterSpec("local", None, spec.workers)
    if spec.kind == "local":
        cpus = os.cpu_count() or 1
        ray.init(num_cpus=max(cpus, spec.workers or 0), **common)
        address, started = "local", True
    elif spec.kind == "ray":
        try:
            ray.init(address=spec.address, **common)
        except Exception as exc:  # noqa: BLE001 - Ray raises several kinds for an unreachable head
            raise ClusterError(f"--cluster {spec.address}: cannot connect ({exc})") from None
    try:
        yield _info(ray, address, started)
    finally:
        ray.shutdown()


def _info(ray, address: str, started: bool) -> ClusterInfo:
    res = ray.cluster_resources()
    return ClusterInfo(address=str(address), cpus=float(res.get("CPU", 0.0)), gpus=float(res.get("GPU", 0.0)),
                       started_here=started)


class Worker:
    """Base of a pool's workers: the Mitsuba variant set and Dr.Jit's thread count fixed once per process.

    Args:
        threads: Dr.Jit threads of this worker (its share of the node's cores; None: Dr.Jit's default).
    """

    def __init__(self, threads: int | None = None) -> None:
        from lftransfer.backend import mitsuba, set_drjit_threads

        mitsuba()
        if threads:
            set_drjit_threads(max(MIN_THREADS, int(threads)))

    def pid(self) -> int:
        """The worker's process id (its set-up is done when this answers)."""
        return os.getpid()


class WorkerPool:
    """Warm workers of one kind (a class whose methods do the work), spread over the cluster.

    Args:
        worker_class: a subclass of :class:`Worker`; each worker is an instance of it in its own process, made
            with ``args`` (the scene, the rig model: sent once, not with every task) and ``threads=``.
        args: its constructor's arguments.
        info: the cluster (:func:`connect`).
        workers: how many (None: :meth:`ClusterInfo.default_workers`).

    Example:
        >>> with connect(ClusterSpec("local")) as info:                          # doctest: +SKIP
        ...     pool = WorkerPool(FrameWorker, (scene, options, model, settings), info)
        ...     for index, result in pool.map("transfer", [(0, 0.0), (1, 0.04)]):
        ...         write(index, result)
    """

    def __init__(self, worker_class: type, args: Sequence[Any], info: ClusterInfo, workers: int | None = None) -> None:
        ray = _ray()
        self._ray, self.info = ray, info
        n = workers or info.default_workers()
        per = {"num_cpus": info.cpus / n}
        if info.gpus >= 1:
            per["num_gpus"] = min(1.0, info.gpus / n)
        # At least 2: with a pool of one thread, Mitsuba's EXR reader (the ground-truth cache) never returns
        # (mitsuba 3.9.1, drjit 1.5.0).
        threads = max(MIN_THREADS, int(round(info.cpus / n)))
        remote = ray.remote(max_restarts=MAX_RETRIES, max_task_retries=MAX_RETRIES, **per)(worker_class)
        # The arguments go into the object store once; the pool holds them so that a restarted worker finds them.
        self._args = [ray.put(a) for a in args]
        self.actors = [remote.remote(*self._args, threads=threads) for _ in range(n)]
        # The first call on each worker waits for its set-up (variant, rig) and says which process it is.
        self.pids = ray.get([a.pid.remote() for a in self.actors])

    def describe(self) -> dict:
        """Where the work ran, for reports: the cluster's address, the workers, the cluster's CPUs and GPUs."""
        return {"address": self.info.address, "workers": len(self.actors), "cpus": self.info.cpus,
                "gpus": self.info.gpus}

    def map(self, method: str, items: Iterable[tuple]) -> Iterator[tuple[tuple, Any]]:
        """Run ``worker.method(*item)`` for every item, each on the next free worker.

        Yields:
            (item, result) as each finishes (not in the items' order).

        Raises:
            The task's own exception where a task failed; :class:`ClusterError` where a worker kept dying.
        """
        ray = self._ray
        from ray.exceptions import RayActorError, RayTaskError

        queue = list(items)
        queue.reverse()
        running: dict = {}
        free = list(self.actors)
        while queue or running:
            while queue and free:
                actor, item = free.pop(), queue.pop()
                running[getattr(actor, method).remote(*item)] = (actor, item)
            done, _ = ray.wait(list(running), num_returns=1)
            actor, item = running.pop(done[0])
            try:
                result = ray.get(done[0])
            except RayTaskError as exc:
                raise exc.as_instanceof_cause() from None
            except RayActorError as exc:
                raise ClusterError(f"a worker died {MAX_RETRIES + 1} times running {method}{item}: {exc}") from None
            free.append(actor)
            yield item, result


class LocalPool:
    """A :class:`WorkerPool`'s ``map`` in this process: one worker (a :class:`Worker` made here), the items one
    after the other, in their order. The same code then drives work in one process and on a cluster.

    Args:
        worker: the worker.
    """

    def __init__(self, worker) -> None:
        self.worker = worker

    def map(self, method: str, items: Iterable[tuple]) -> Iterator[tuple[tuple, Any]]:
        """(item, ``worker.method(*item)``) for every item, in order."""
        for item in items:
            yield item, getattr(self.worker, method)(*item)
