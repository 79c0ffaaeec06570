"""Output paths are checked before any work, with one line naming the path and what is wrong."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from lftransfer.runs.paths import OutputPathError, _probe, check_cache_dir, check_output_dir, check_output_file


@pytest.fixture
def read_only_dir(tmp_path):
    """A folder no file can be created in: a mode 555 folder, or (as root, whom modes do not stop) sysfs."""
    if os.geteuid() != 0:
        d = tmp_path / "read-only"
        d.mkdir()
        d.chmod(0o555)
        yield d
        d.chmod(0o755)
        return
    d = Path("/sys")
    if not d.is_dir() or _probe(d) is None:
        pytest.skip("running as root and /sys takes files: no read-only folder to test with")
    yield d


def test_01_a_file_where_a_folder_is_expected(tmp_path):
    f = tmp_path / "notes.txt"
    f.write_text("x")
    with pytest.raises(OutputPathError, match=r"^--out .*notes\.txt: is a file, expected a folder$"):
        check_output_dir(f)
    with pytest.raises(OutputPathError, match=r"notes\.txt is a file, so the folder cannot be made"):
        check_output_dir(f / "run")


def test_02_a_folder_that_cannot_be_written(read_only_dir):
    with pytest.raises(OutputPathError, match=r"cannot write there: "):
        check_output_dir(read_only_dir)
    with pytest.raises(OutputPathError, match=r"cannot write there \(in .*, where it would be made\)"):
        check_output_dir(read_only_dir / "new" / "run")


def test_03_a_folder_where_a_file_is_expected(tmp_path):
    with pytest.raises(OutputPathError, match=r"is a folder, expected a file name \(e\.g\. --out .*calibration\.json\)"):
        check_output_file(tmp_path, "--out", "calibration.json")
    f = tmp_path / "plain"
    f.write_text("x")
    with pytest.raises(OutputPathError, match=r"plain is a file"):
        check_output_file(f / "calibration.json")


def test_04_good_paths_pass_and_leave_nothing(tmp_path):
    assert check_output_dir(tmp_path / "a" / "b") == tmp_path / "a" / "b"
    assert check_output_file(tmp_path / "c" / "calibration.json").name == "calibration.json"
    assert not (tmp_path / "a").exists() and list(tmp_path.iterdir()) == []     # probes leave nothing


def test_05_cache_folder_says_how_to_choose_another(tmp_path, read_only_dir):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(OutputPathError, match=r"ground-truth cache .*file.*LFT_CACHE_DIR.*--no-cache"):
        check_cache_dir(blocker / "ground_truth")
    with pytest.raises(OutputPathError, match=r"ground-truth cache .*cannot write there"):
        check_cache_dir(read_only_dir / "lftransfer" / "ground_truth")
