"""The project's npz files: atomic writes and reads whose failures tell the user what to do."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from physpose.cache import UNREADABLE_NPZ, npz_arrays, save_npz
from physpose.errors import PhysposeError


def write_npz(path: str | Path, arrays: dict[str, np.ndarray]) -> Path:
    """Write compressed arrays to exactly `path` (numpy would add ".npz" to a name without it);
    a crash never leaves a half-written file under `path`."""
    path = Path(path)
    if path.is_dir():
        raise PhysposeError("cannot write the npz file: this is a folder", path=path,
                            remedy=f"pass a file path, e.g. {path / 'name.npz'}")
    save_npz(path, arrays)
    return path


def read_npz(path: str | Path, *, what: str, remedy: str) -> dict[str, np.ndarray]:
    """All arrays of an npz file (allow_pickle=False); PhysposeError if it cannot be read."""
    try:
        return npz_arrays(path)
    except UNREADABLE_NPZ as exc:
        raise PhysposeError(f"not a readable {what} npz ({exc})", path=path,
                            remedy=remedy) from None
