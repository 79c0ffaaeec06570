"""Sequences on a Ray cluster (``lft render --mode converged --cluster``): the same frames as in one process, and a
worker killed in the middle of a job is replaced without the job noticing."""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import numpy as np
import pytest

from lftransfer.runs.cluster import ClusterSpec
from lftransfer.settings import Overrides
from lftransfer.runs.pipeline import RigSpec, RunOptions
from lftransfer.runs.sequence import SequenceError, SequenceOptions, render_sequence
from lftransfer.imageio_utils import read_exr

from tests.runs.test_sequence import _moving_scene


def test_01_cluster_spec():
    assert ClusterSpec.parse("auto") == ClusterSpec("auto")
    assert ClusterSpec.parse("local", workers=2) == ClusterSpec("local", None, 2)
    spec = ClusterSpec.parse("ray://head.example:10001")
    assert (spec.kind, spec.address, str(spec)) == ("ray", "ray://head.example:10001", "ray://head.example:10001")
    for bad in ("ray://nohost", "ray://h:port", "ray://h:70000", "slurm", ""):
        with pytest.raises(ValueError, match="expected 'auto', 'local' or 'ray://HOST:PORT'"):
            ClusterSpec.parse(bad)
    with pytest.raises(ValueError, match="--workers"):
        ClusterSpec.parse("local", workers=0)


def test_02_only_independent_frames_of_the_simulated_rig(tmp_path):
    """The live loop is sequential and a physical rig or a recording is one device: both refuse a cluster."""
    with pytest.raises(SequenceError, match="needs --mode converged"):
        SequenceOptions(mode="live", cluster=ClusterSpec("local"))
    seq = SequenceOptions(mode="converged", cluster=ClusterSpec("local"))
    options = RunOptions(rig=RigSpec("replay", tmp_path), rig_model="nominal")
    with pytest.raises(SequenceError, match="needs the simulated rig"):
        render_sequence(_moving_scene(), tmp_path / "out", options, seq)


def _busy_workers() -> list[int]:
    """Process ids of the cluster's frame workers that are running a frame now (Ray names a worker's process after
    the task it runs)."""
    pids = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                cmd = (entry / "cmdline").read_bytes()
            except OSError:
                continue
            if cmd.startswith(b"ray::FrameWorker.transfer"):
                pids.append(int(entry.name))
    return pids


@pytest.mark.slow
@pytest.mark.ray
def test_03_cluster_sequence_equals_one_process_and_survives_a_killed_worker(variant, tmp_path):
    """A 4-frame converged sequence with its ground truth, on a local cluster of 2 workers, is bit-identical to the
    same sequence in one process (frames, metrics); one worker is killed while it renders a frame, and Ray's
    replacement renders it again."""
    pytest.importorskip("ray")
    if not Path("/proc/self/cmdline").is_file():
        pytest.skip("needs /proc to find a busy worker")
    scene = _moving_scene()
    options = RunOptions(rig_model="oracle", truth_seed=3, use_cache=False, settings=Overrides(gt_spp=16))
    one = render_sequence(scene, tmp_path / "one", options, SequenceOptions(mode="converged", frames=4, verify_every=1))

    killed = []

    def kill_one(record, done, total):
        """After a frame is written, kill a worker that is rendering another (the first time one is busy)."""
        if not killed:
            busy = _busy_workers()
            if busy:
                os.kill(busy[0], signal.SIGKILL)
                killed.append(busy[0])

    seq = SequenceOptions(mode="converged", frames=4, verify_every=1, cluster=ClusterSpec("local", workers=2))
    many = render_sequence(scene, tmp_path / "many", options, seq, progress=kill_one)
    assert killed, "no worker was busy when a frame was written: nothing was killed"
    assert many["cluster"]["workers"] == 2
    assert [f["index"] for f in many["frames"]] == [0, 1, 2, 3]
    for i in range(4):
        a = read_exr(tmp_path / "one" / "frames" / f"{i:04d}.exr")
        b = read_exr(tmp_path / "many" / "frames" / f"{i:04d}.exr")
        assert np.array_equal(a, b), f"frame {i} differs between the cluster and one process"
        assert many["frames"][i]["metrics"] == one["frames"][i]["metrics"]
        assert many["frames"][i]["metrics"]["psnr_objects_db"] is not None
    # the frames differ from each other (the cube moves): equality above is not equality of empty images
    assert not np.array_equal(read_exr(tmp_path / "one" / "frames" / "0000.exr"),
                              read_exr(tmp_path / "one" / "frames" / "0003.exr"))
    assert json.loads((tmp_path / "many" / "status.json").read_text())["state"] == "complete"
    assert (tmp_path / "many" / "composite.mp4").stat().st_size > 0


@pytest.mark.slow
@pytest.mark.ray
def test_04_quiet_reference_on_a_cluster_equals_one_process(tmp_path):
    """A quiet reference spread over a local cluster of 2 workers (one part of each round per worker) is
    bit-identical to the same reference split alike in one process (one round after the first, to keep it short);
    split in two it differs from the reference in one part (other seeds), so the equality is not of one render with
    itself."""
    pytest.importorskip("ray")
    from lftransfer.runs.reference_pool import reference_renderer
    from lftransfer.sim.reference import quiet_ground_truth

    from tests.sim.test_reference import tiny_run

    oracle, judge = tiny_run(tmp_path)
    local, ref_local = quiet_ground_truth(oracle.world, judge, spp=16, max_rounds=1, use_cache=False, parts=2)
    with reference_renderer(ClusterSpec("local", workers=2), use_cache=False) as (render, parts):
        assert parts == 2
        many, ref_many = quiet_ground_truth(oracle.world, judge, spp=16, max_rounds=1, use_cache=False,
                                            parts=parts, render=render)
    assert ref_many.parts == 2 and ref_many.rounds == 2 and ref_many.noise < ref_many.error
    assert (ref_many.spp, ref_many.noise, ref_many.error) == (ref_local.spp, ref_local.noise, ref_local.error)
    for name in ("union", "real", "synthetic", "alpha_real", "alpha_synthetic"):
        assert np.array_equal(getattr(many, name), getattr(local, name)), name
    one, ref_one = quiet_ground_truth(oracle.world, judge, spp=16, max_rounds=1, use_cache=False)
    assert ref_one.spp == ref_many.spp and not np.array_equal(one.union, many.union)
