"""Stage cache: results stored as npz files keyed by what produced them, not by file existence.

A key is the sha256 of (stage name, stage code version, sha256 of each input file's bytes, the
stage config as sorted JSON, any extra JSON-able values). Change any of these and the key
changes, so a stale result is never returned. Usage:

    key = stage_key("observe", version=OBSERVE_VERSION, files=[video], config=cfg)
    cache = Cache("observe")
    arrays = cache.get(key)            # dict of arrays, or None on a miss
    if arrays is None:
        arrays = compute(...)
        cache.put(key, arrays)         # atomic: temp file + rename

Entries live in `paths.cache_dir()/<stage>/<key>.npz` (PHYSPOSE_CACHE_DIR overrides the root).
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import logging
import os
import re
import secrets
import zipfile
import zlib
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from physpose.errors import PhysposeError
from physpose.paths import cache_dir

CACHE_FORMAT = 1  # bump if the key recipe or the entry layout changes
_CHUNK = 1 << 20  # bytes read at a time when hashing files
# What np.load raises for an npz file that is damaged, cut short or not an npz at all
# (zlib.error: a compressed member overwritten, found only as its array is read).
UNREADABLE_NPZ = (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error)
_log = logging.getLogger(__name__)
# (resolved path, size, mtime_ns) -> sha256 hex, so a file is hashed once per process.
_digests: dict[tuple[str, int, int], str] = {}


def npz_arrays(path: str | Path) -> dict[str, np.ndarray]:
    """Every array of an npz archive (allow_pickle=False); one of UNREADABLE_NPZ where the file
    is damaged or holds something else (np.load gives a bare array for a .npy)."""
    data = np.load(path, allow_pickle=False)
    if not isinstance(data, np.lib.npyio.NpzFile):
        raise ValueError("not an npz archive (it holds a single array)")
    with data:
        return {k: data[k] for k in data.files}


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside `path`; on success rename it to `path`, else delete it.

    Readers never see a half-written file, and a failure leaves an existing `path` untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.{secrets.token_hex(4)}.tmp{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def save_npz(path: str | Path, arrays: Mapping[str, Any], *, compressed: bool = True) -> None:
    """Write arrays as an npz archive to exactly `path`, atomically (atomic_path). The archive
    is built in memory first, so a write that fails (a full disk) raises a plain OSError:
    numpy's zip writer, failing on the file itself, left a ZipFile whose clean-up printed
    "Exception ignored ... seek of closed file" beside the run's own message."""
    buffer = io.BytesIO()
    (np.savez_compressed if compressed else np.savez)(
        buffer, **{k: np.asarray(v) for k, v in arrays.items()})
    with atomic_path(path) as tmp:
        tmp.write_bytes(buffer.getbuffer())


# atomic_path's temporary names: .<stem>.<pid>.<8 hex>.tmp<suffix>
_TEMP_NAME = re.compile(r"\..+\.(\d+)\.[0-9a-f]{8}\.tmp(\.[^.]*)?")


def leftover_temp_files(folder: str | Path) -> list[Path]:
    """atomic_path's temporary files in `folder` whose writing process is gone (a run killed
    while it wrote them). Where processes cannot be asked about (not POSIX), none."""
    if os.name != "posix":
        return []
    found = []
    for path in Path(folder).glob(".*.tmp*"):
        match = _TEMP_NAME.fullmatch(path.name)
        if match and not _running(int(match.group(1))):
            found.append(path)
    return found


def _running(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)  # POSIX: asks, sends nothing
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # someone else's process
    return True


def file_digest(path: str | Path) -> str:
    """sha256 hex digest of a file's bytes, streamed; memoised on (path, size, mtime)."""
    path = Path(path)
    try:
        st = path.stat()
    except FileNotFoundError:
        raise PhysposeError("file not found", path=path, remedy="check the path") from None
    memo = (str(path.resolve()), st.st_size, st.st_mtime_ns)
    if memo not in _digests:
        h = hashlib.sha256()
        with path.open("rb") as fh:
            while chunk := fh.read(_CHUNK):
                h.update(chunk)
        _digests[memo] = h.hexdigest()
    return _digests[memo]


def _jsonable(value: Any) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _jsonable(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return {"dtype": str(value.dtype), "shape": list(value.shape),
                "sha256": hashlib.sha256(np.ascontiguousarray(value).tobytes()).hexdigest()}
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    raise TypeError(f"cannot put a {type(value).__name__} into a cache key")


def canonical_json(value: Any) -> str:
    """Deterministic JSON of a config (dataclass, mapping, sequence, array or scalar)."""
    return json.dumps(_jsonable(value), sort_keys=True, separators=(",", ":"), allow_nan=True)


def stage_key(stage: str, *, version: str | int, files: Iterable[str | Path] = (),
              config: Any = None, extra: Any = None) -> str:
    """Key (64 hex chars) of a stage result from its inputs' bytes, config and code version."""
    recipe = {
        "cache_format": CACHE_FORMAT,
        "stage": stage,
        "version": version,
        "files": [file_digest(f) for f in files],
        "config": _jsonable(config),
        "extra": _jsonable(extra),
    }
    return hashlib.sha256(canonical_json(recipe).encode()).hexdigest()


class Cache:
    """The npz entries of one stage under `root/<stage>/` (root: paths.cache_dir())."""

    def __init__(self, stage: str, root: str | Path | None = None):
        if not stage or any(c in stage for c in "/\\") or stage.startswith("."):
            raise ValueError(f"invalid stage name {stage!r}")
        self.stage = stage
        self.dir = Path(root if root is not None else cache_dir()) / stage

    def path(self, key: str) -> Path:
        """Where the entry for `key` is (or would be) stored."""
        if len(key) < 16 or not all(c in "0123456789abcdef" for c in key):
            raise ValueError(f"invalid cache key {key!r}")
        return self.dir / f"{key}.npz"

    def get(self, key: str) -> dict[str, np.ndarray] | None:
        """The arrays stored under `key`, or None if absent. An unreadable entry (e.g. a
        disk-full leftover) is logged, deleted and reported as a miss."""
        path = self.path(key)
        if not path.is_file():
            return None
        try:
            return npz_arrays(path)
        except UNREADABLE_NPZ as exc:
            _log.warning("dropping unreadable cache entry %s (%s)", path, exc)
            path.unlink(missing_ok=True)
            return None

    def put(self, key: str, arrays: Mapping[str, np.ndarray]) -> Path | None:
        """Store arrays under `key` atomically (temp file in the same folder, then rename).
        A cache that cannot be written (a file in the way, no permission, a full disk) only
        costs the next run its reuse: logged, and None returned."""
        path = self.path(key)
        try:
            save_npz(path, arrays)
        except OSError as exc:
            _log.warning("cannot store the %s result in the cache at %s (%s); going on "
                         "without it. set PHYSPOSE_CACHE_DIR to a folder you may write to",
                         self.stage, self.dir, exc.strerror or exc)
            return None
        return path

    def clear(self) -> int:
        """Delete every entry of this stage; returns how many were removed."""
        removed = 0
        for p in self.dir.glob("*.npz"):
            p.unlink(missing_ok=True)
            removed += 1
        return removed
