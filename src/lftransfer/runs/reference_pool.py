"""A quiet reference's rounds spread over the workers of a Ray cluster (docs/architecture.md, "A quiet reference").

:func:`lftransfer.sim.reference.quiet_ground_truth` splits each later round into parts, one render each with its
own seeds; :func:`reference_renderer` gives it a ``render`` that sends the parts to warm workers
(:class:`~lftransfer.runs.cluster.WorkerPool`) and hands their ground truths back in the parts' order, so the
reference is the same as the same parts rendered in one process.
"""

from __future__ import annotations

from contextlib import contextmanager
from typing import Callable, Iterator

from lftransfer.runs.cluster import ClusterSpec, Worker

__all__ = ["ReferenceWorker", "reference_renderer"]


class ReferenceWorker(Worker):
    """A cluster worker of ground-truth renders (:func:`lftransfer.sim.reference.render_jobs`)."""

    def render(self, index: int, scene, spp: int, seeds: tuple[int, int], crop, use_cache: bool):
        """Part ``index``'s ground truth (the index travels back with it)."""
        from lftransfer.sim.reference import render_jobs

        return render_jobs(scene, [(spp, seeds, crop)], use_cache=use_cache)[0]


@contextmanager
def reference_renderer(spec: ClusterSpec | None, *, use_cache: bool = True,
                       step: Callable[[str], None] | None = None) -> Iterator[tuple[Callable | None, int]]:
    """(``render``, ``parts``) for :func:`~lftransfer.sim.reference.quiet_ground_truth`: on the cluster ``spec``,
    a render over its workers and one part per worker; without one, (None, 1): the rounds render in this
    process."""
    if spec is None:
        yield None, 1
        return
    from lftransfer.runs.cluster import WorkerPool, connect

    say = step or (lambda _msg: None)
    say(f"start the cluster ({spec}) for the quiet reference")
    with connect(spec) as info:
        pool = WorkerPool(ReferenceWorker, (), info, spec.workers)

        def render(scene, jobs):
            items = [(j, scene, n, seeds, crop, use_cache) for j, (n, seeds, crop) in enumerate(jobs)]
            done = {item[0]: gt for item, gt in pool.map("render", items)}
            return [done[j] for j in range(len(jobs))]

        yield render, len(pool.actors)
