"""BLAS threads beside Dr.Jit (lftransfer.backend, docs/performance.md "BLAS threads beside Dr.Jit"): OpenBLAS's
threads spin after each product and take the cores from the renderer's kernels, so every pipeline step runs with
them bounded, whatever raised them before."""

from __future__ import annotations

import pytest
from threadpoolctl import threadpool_limits

from lftransfer import backend, choices
from lftransfer.runs.pipeline import RunOptions, open_rig
from lftransfer.scenes import quick_scene
from lftransfer.scenes import builtin_scene, load_scene
from lftransfer.transfer.bounce import TransferSettings, run_transfer
from lftransfer.transfer.live import LiveTransfer
from lftransfer.transfer.synthetic_side import SyntheticSide


@pytest.fixture
def fresh_setting(monkeypatch):
    """The BLAS setting unresolved (no command line, no environment), and the libraries' threads put back after
    the test as they were before it."""
    monkeypatch.setattr(backend, "_blas_threads", None)
    monkeypatch.delenv(backend.BLAS_THREADS_ENV, raising=False)
    before = backend.blas_thread_counts()
    yield
    if before:
        threadpool_limits(max(before.values()), user_api="blas")


@pytest.fixture(scope="module")
def small(variant):
    scene = quick_scene(load_scene(builtin_scene("fig4")))
    settings = TransferSettings(angular_samples=scene.rig.angular_samples, bounces=1, bounce_views=False)
    return scene, settings


def _threads_during_render(monkeypatch) -> list[dict[str, int]]:
    """Record every BLAS library's threads each time the synthetic side renders (inside the pipeline step)."""
    seen: list[dict[str, int]] = []
    original = SyntheticSide.render

    def render(self, *args, **kwargs):
        seen.append(backend.blas_thread_counts())
        return original(self, *args, **kwargs)

    monkeypatch.setattr(SyntheticSide, "render", render)
    return seen


def _raised_to_two() -> bool:
    """Raise every BLAS library to two threads; False where a library will not take two (a one-core machine)."""
    threadpool_limits(2, user_api="blas")
    return all(n == 2 for n in backend.blas_thread_counts().values())


def test_01_the_setting_resolves_once_with_clear_errors(fresh_setting, monkeypatch):
    assert backend.blas_threads() == choices.DEFAULT_BLAS_THREADS == 1
    monkeypatch.setenv(backend.BLAS_THREADS_ENV, "3")
    assert backend.blas_threads() == 3
    monkeypatch.setenv(backend.BLAS_THREADS_ENV, "two")
    with pytest.raises(ValueError, match="LFT_BLAS_THREADS: expected an integer >= 0.*'two'"):
        backend.blas_threads()
    for bad in (-1, 1.5, "x", True):
        with pytest.raises(ValueError, match="blas_threads: expected an integer >= 0"):
            backend.set_blas_threads(bad)
    backend.set_blas_threads(2)          # the command line wins over the environment
    assert backend.blas_threads() == 2
    monkeypatch.setattr(backend, "_blas_threads", None)


def test_02_bound_blas_bounds_every_loaded_library(fresh_setting):
    import cv2  # noqa: F401 - every BLAS our dependencies bring is loaded
    import scipy.linalg  # noqa: F401

    raised = _raised_to_two()
    assert backend.bound_blas() == 1
    counts = backend.blas_thread_counts()
    assert len(counts) >= 3 and set(counts.values()) == {1}, counts    # NumPy's, SciPy's, OpenCV's OpenBLAS
    if not raised:
        pytest.skip("the BLAS libraries take one thread only on this machine: no unbounded state to undo")


def test_03_a_live_step_and_a_transfer_run_with_blas_bounded(small, fresh_setting, monkeypatch):
    """Threads raised to two just before: the live step and the bounce loop bound them again before rendering.
    Negative control: with the bound switched off (``LFT_BLAS_THREADS=0``) the same probe sees two threads."""
    scene, settings = small
    opened = open_rig(scene, RunOptions(truth_seed=None))
    live = LiveTransfer(opened.rig, opened.oracle.model, scene.synthetic_part(), settings)
    seen = _threads_during_render(monkeypatch)
    if not _raised_to_two():
        pytest.skip("the BLAS libraries take one thread only on this machine")
    live.step(0.0)
    assert seen and all(set(s.values()) == {1} for s in seen), seen
    seen.clear()
    _raised_to_two()
    run_transfer(opened.rig, opened.oracle.model, scene.synthetic_part(), settings)
    assert len(seen) == settings.bounces + 1 and all(set(s.values()) == {1} for s in seen), seen

    seen.clear()
    monkeypatch.setenv(backend.BLAS_THREADS_ENV, "0")
    _raised_to_two()
    live.step(0.0)
    assert seen and all(set(s.values()) == {2} for s in seen), seen
