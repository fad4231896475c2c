"""Where physpose finds its built-in data and the shared evaluation material."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

from physpose.errors import PhysposeError

# The repository root when installed editable from a checkout (src/physpose/paths.py -> ../..).
_CHECKOUT = Path(__file__).resolve().parents[2]


def project_root() -> Path:
    """The checkout root if physpose runs from one, else the working directory."""
    return _CHECKOUT if (_CHECKOUT / "pyproject.toml").is_file() else Path.cwd()


def data_dir() -> Path:
    """Git-ignored folder for data the set-up fetches (override: PHYSPOSE_DATA_DIR)."""
    return Path(os.environ.get("PHYSPOSE_DATA_DIR", project_root() / "data"))


def cache_dir() -> Path:
    """Stage cache folder (override: PHYSPOSE_CACHE_DIR)."""
    return Path(os.environ.get("PHYSPOSE_CACHE_DIR", project_root() / ".cache" / "physpose"))


def shared_data_dir() -> Path:
    """The evaluation material beside the project (override: PHYSPOSE_SHARED_DATA)."""
    return Path(os.environ.get("PHYSPOSE_SHARED_DATA", project_root().parent / "shared" / "data"))


def pose2sim_demo_dir() -> Path:
    """The pose2sim single-person demo (4 calibrated views), fetched by `make data`."""
    return data_dir() / "pose2sim" / "Demo_SinglePerson"


def sports2d_demo_dir() -> Path:
    """Sports2D's two-person demo video (demo.mp4), fetched by `make data`."""
    return data_dir() / "sports2d"


def check_output_folder(path: str | Path, option: str = "--out") -> Path:
    """Refuse, before any long work, an output folder that could not be written: a path that
    is a file, or whose nearest existing parent is a file or not writable. Creates nothing."""
    path = Path(path)
    existing = next(p for p in (path, *path.absolute().parents) if p.exists())
    if not existing.is_dir():
        problem = "exists and is not a folder" if existing == path else \
            f"cannot be a folder: {existing} is a file"
        raise PhysposeError(f"output path {problem}", path=path,
                            remedy=f"pass a folder for {option}")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise PhysposeError(f"cannot write into {existing}", path=path,
                            remedy=f"pass a folder you may write to for {option}")
    return path


def check_output_file(path: str | Path, suffix: str | None = None, option: str = "--out"
                      ) -> Path:
    """Refuse, before the work, an output file that could not be written: a folder, a path
    under a file or an unwritable folder, or (with `suffix`) another kind of file."""
    path = Path(path)
    if path.is_dir():
        raise PhysposeError(f"{option} is a folder; it names the file to write", path=path,
                            remedy=f"pass a file name{f' ending in {suffix}' if suffix else ''}")
    if suffix is not None and path.suffix.lower() != suffix:
        raise PhysposeError(f"{option} does not end in {suffix}", path=path,
                            remedy=f"pass a file name ending in {suffix}")
    existing = next(p for p in path.absolute().parents if p.exists())
    if not existing.is_dir():
        raise PhysposeError(f"{option} cannot be written: {existing} is a file", path=path,
                            remedy="pass a file path in a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise PhysposeError(f"cannot write into {existing}", path=path,
                            remedy=f"pass a file in a folder you may write to for {option}")
    return path


@contextlib.contextmanager
def output_folder(path: str | Path) -> Iterator[Path]:
    """Make the output folder for the work inside the block. If the work fails, the folders
    this made (the output folder, its new parents and what was made inside it) are removed
    again where they stayed empty, so a failed run leaves no empty folder behind; a file, and
    a folder that was there before, are never touched."""
    path = Path(path)
    made = [p for p in (path, *path.parents) if not p.exists()]
    path.mkdir(parents=True, exist_ok=True)
    try:
        yield path
    except BaseException:
        if made:
            inner = sorted((p for p in path.rglob("*") if p.is_dir()), key=lambda p: -len(p.parts))
            for folder in (*inner, *made):  # deepest first
                with contextlib.suppress(OSError):
                    folder.rmdir()  # only succeeds on an empty folder
        raise
