"""Per-window checkpoints: a run folder keyed by the inputs and the config, one npz per window.

An interrupted run finds the windows it already finished and continues after them; a change
of any input (kinematic estimate, detections, camera, body model) or of the config gives a
new key and so a new folder, never a stale result.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from physpose.cache import UNREADABLE_NPZ, npz_arrays, save_npz, stage_key
from physpose.paths import cache_dir

_log = logging.getLogger(__name__)

CHECKPOINT_VERSION = 8  # bump when the optimisation's results change for the same inputs


def run_key(config_identity: dict, inputs: dict) -> str:
    """Key (64 hex chars) of a dynamics run."""
    return stage_key("dynamics", version=CHECKPOINT_VERSION, config=config_identity,
                     extra=inputs)


def run_folder(key: str, root: str | Path | None = None) -> Path:
    """Where a run's window files live (default: the stage cache, ``<cache>/dynamics``)."""
    base = Path(root) if root is not None else cache_dir() / "dynamics"
    return base / key[:24]


def window_path(folder: Path, index: int) -> Path:
    return folder / f"window_{index:03d}.npz"


def save_window(folder: Path, index: int, arrays: dict[str, np.ndarray], record: dict
                ) -> Path | None:
    """Write one finished window atomically (arrays plus a JSON record). A folder that cannot
    be written (a file in the way, no permission, a full disk) costs only the resumption:
    logged, and None returned."""
    path = window_path(folder, index)
    try:
        save_npz(path, {"record_json": np.array(json.dumps(record)), **arrays},
                 compressed=False)
    except OSError as exc:
        _log.warning("%s: cannot write this window's checkpoint (%s); the run goes on, but "
                     "an interruption would optimise this window again. Free space there or "
                     "allow writing (reconstruct keeps its checkpoints in --out's "
                     "dynamics_windows, the benchmark under PHYSPOSE_CACHE_DIR)", path,
                     exc.strerror or exc)
        return None
    return path


def load_window(folder: Path, index: int) -> tuple[dict[str, np.ndarray], dict] | None:
    """A finished window's (arrays, record), or None when it has not been written. An
    unreadable file (a disk filled up, a copy cut short) is logged, deleted and optimised
    again, like a window that was never written."""
    path = window_path(folder, index)
    if not path.is_file():
        return None
    try:
        arrays = npz_arrays(path)
        record = json.loads(str(arrays.pop("record_json")))
    except (*UNREADABLE_NPZ, KeyError) as exc:  # KeyError: no record inside
        _log.warning("%s: unreadable checkpoint (%s); this window is optimised again", path, exc)
        path.unlink(missing_ok=True)
        return None
    return arrays, record
