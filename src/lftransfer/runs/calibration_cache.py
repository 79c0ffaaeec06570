"""The calibration cache: a simulated rig's calibration kept under a hash of what it depends on, checked on read.

On the simulated rig a calibration is a function of the scene's hidden world and devices (everything in the scene
file but its synthetic objects, its render settings and its effect), the truth seed, the rays per LF camera pixel
and the code. :func:`inputs_sha256` hashes all of them (the code as the SHA-256 of the package's Python files, so
any change of the code calibrates again), and every command that would calibrate that rig reuses the entry
(``lft run``, ``demo``, ``render``, ``live``, ``bench``; ``--recalibrate`` makes a new one and stores it).

An entry is a folder in :func:`cache_dir` named by the hash's first 20 characters: the three files a calibration
leaves in a run folder (:data:`FILES`), the simulated rig's random streams as they stood after calibrating
(``rig_state.json``: a run from the cache draws the noise the calibrating run drew next, so it gives the same
report) and ``entry.json``, written last, with the whole hash and the SHA-256 of each file. Reading verifies all of
them; an entry that fails (a file missing, changed or swapped, a run that stopped while writing) is reported as a
:class:`~lftransfer.sim.gt_cache.CacheProblem`, so the caller calibrates again and overwrites it. A physical rig
is never cached: it may have moved since.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

from lftransfer.imageio_utils import write_text
from lftransfer.sim.gt_cache import CacheProblem, file_sha256

__all__ = ["FILES", "CachedCalibration", "cache_dir", "code_sha256", "inputs_sha256", "read_entry", "write_entry"]

FORMAT = "lftransfer-calibration-cache/1"
FILES = ("calibration.json", "calibration_errors.json", "calibration_report.html")
"""What a calibration writes beside a run (the file, its errors against the hidden truth, its report)."""
STATE_FILE = "rig_state.json"
ENTRY_FILE = "entry.json"


def cache_dir() -> Path:
    """Folder of cached calibrations: ``$LFT_CALIBRATION_CACHE_DIR``, else ``$LFT_CACHE_DIR/calibration`` or
    ``~/.cache/lftransfer/calibration``."""
    own = os.environ.get("LFT_CALIBRATION_CACHE_DIR")
    if own:
        return Path(own)
    return Path(os.environ.get("LFT_CACHE_DIR", Path.home() / ".cache" / "lftransfer")) / "calibration"


@functools.lru_cache(maxsize=1)
def code_sha256() -> str:
    """SHA-256 (hex) of the package's Python files (their paths and bytes): a calibration made by other code is
    another entry."""
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def inputs_sha256(scene, truth_seed: int | None, capture_spp: int) -> str:
    """SHA-256 (hex) of everything a calibration of the simulated rig of ``scene`` depends on.

    Args:
        scene: the whole ``SceneConfig`` (its synthetic objects, ``[render]`` and ``[effect]`` left out).
        truth_seed: the hidden truth's seed (None: the rig built exactly as its file says).
        capture_spp: rays per LF camera pixel of the simulated rig.
    """
    world = scene.model_dump(mode="json", exclude={"synthetic", "render", "effect", "source"})
    files = {}
    for o in getattr(scene, "real", ()):
        if getattr(o, "file", None):
            files[o.name] = file_sha256(Path(o.file))
    env = getattr(scene, "environment", None)
    if env is not None and env.file is not None:
        files["environment"] = file_sha256(Path(env.file))
    payload = {"world": world, "files": files, "truth_seed": truth_seed, "capture_spp": int(capture_spp),
               "code": code_sha256(), "v": 1}
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()


@dataclass(frozen=True)
class CachedCalibration:
    """A verified entry.

    Attributes:
        folder: the entry's folder (its :data:`FILES`).
        rig_state: the simulated rig's random streams after calibrating (``SimRig.noise_state``).
    """

    folder: Path
    rig_state: dict

    @property
    def calibration_file(self) -> Path:
        return self.folder / FILES[0]

    def copy_to(self, out: Path) -> None:
        """Put the entry's files in ``out`` as the calibration would have written them (an errors file only where
        the entry has one)."""
        out.mkdir(parents=True, exist_ok=True)
        for name in FILES:
            if (self.folder / name).is_file():
                tmp = out / f".{name}.tmp"
                shutil.copyfile(self.folder / name, tmp)
                os.replace(tmp, out / name)


def _folder(inputs: str) -> Path:
    return cache_dir() / inputs[:20]


def read_entry(inputs: str) -> CachedCalibration | CacheProblem | None:
    """The cached calibration for these inputs, verified: None when there is none; a ``CacheProblem`` when the
    entry cannot be used."""
    folder = _folder(inputs)
    if not folder.is_dir():
        return None

    def problem(reason: str) -> CacheProblem:
        return CacheProblem(folder, reason, what="calibration cache entry", action="calibrating again")

    try:
        entry = json.loads((folder / ENTRY_FILE).read_text(encoding="utf-8"))
    except FileNotFoundError:
        return problem(f"has no {ENTRY_FILE} (written by a run that stopped)")
    except (OSError, ValueError) as exc:
        return problem(f"has an unreadable {ENTRY_FILE} ({exc})")
    if not isinstance(entry, dict) or entry.get("format") != FORMAT:
        return problem(f"has an {ENTRY_FILE} of another format")
    if entry.get("inputs_sha256") != inputs:
        return problem("belongs to other inputs (swapped or copied from another entry)")
    sums = entry.get("sha256")
    if not isinstance(sums, dict) or FILES[0] not in sums or STATE_FILE not in sums:
        return problem(f"has an {ENTRY_FILE} without its files' checksums")
    for name, expected in sums.items():
        try:
            actual = file_sha256(folder / name)
        except OSError as exc:
            return problem(f"lacks {name} ({exc.strerror or exc})")
        if actual != expected:
            return problem(f"has a {name} that does not match its checksum (corrupt, truncated or replaced)")
    try:
        state = json.loads((folder / STATE_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        return problem(f"has an unreadable {STATE_FILE} ({exc})")
    return CachedCalibration(folder, state)


def write_entry(inputs: str, run_folder: Path, rig_state: dict) -> Path:
    """Store the calibration files a run wrote in ``run_folder`` (:data:`FILES`, those that exist) with the rig's
    random streams after calibrating; ``entry.json`` is removed first and written last, so a half-written entry
    is never read as whole.

    Returns:
        The entry's folder.
    """
    folder = _folder(inputs)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / ENTRY_FILE).unlink(missing_ok=True)
    sums = {}
    for name in FILES:
        (folder / name).unlink(missing_ok=True)
        if (run_folder / name).is_file():
            tmp = folder / f".{name}.tmp"
            shutil.copyfile(run_folder / name, tmp)
            os.replace(tmp, folder / name)
            sums[name] = file_sha256(folder / name)
    write_text(folder / STATE_FILE, json.dumps(rig_state) + "\n")
    sums[STATE_FILE] = file_sha256(folder / STATE_FILE)
    write_text(folder / ENTRY_FILE, json.dumps({"format": FORMAT, "inputs_sha256": inputs, "sha256": sums},
                                               indent=1) + "\n")
    return folder
