"""Shared fixtures. Mitsuba variants are parametrised like Mitsuba's own tests: missing back-ends are skipped."""

from __future__ import annotations

import os

import pytest

import lftransfer  # noqa: F401  (points Dr.Jit at a suitable libLLVM)


def _variants():
    wanted = os.environ.get("LFT_TEST_VARIANTS", "llvm_ad_rgb,cuda_ad_rgb").split(",")
    return [v.strip() for v in wanted if v.strip()]


@pytest.fixture(scope="session", params=_variants())
def variant(request):
    """Set a Mitsuba variant for the test; skip where its back-end is missing."""
    import mitsuba as mi
    import drjit as dr

    name = request.param
    try:
        mi.set_variant(name)
        backend = dr.JitBackend.CUDA if name.startswith("cuda") else dr.JitBackend.LLVM
        if not dr.has_backend(backend):
            raise RuntimeError("back-end missing")
    except Exception as exc:  # noqa: BLE001
        pytest.skip(f"variant {name} unavailable: {exc}")
    os.environ["LFT_VARIANT"] = name
    yield name
    os.environ.pop("LFT_VARIANT", None)


@pytest.fixture(autouse=True)
def _cache_dir(tmp_path_factory, tmp_path, monkeypatch):
    """Keep ground-truth caches of tests out of the user's cache (shared by the session's tests), and give each test
    a calibration cache of its own: a test that stands a fake calibration in for the real one must not leave it
    for the next."""
    monkeypatch.setenv("LFT_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "cache"))
    monkeypatch.setenv("LFT_CALIBRATION_CACHE_DIR", str(tmp_path / "calibration_cache"))
