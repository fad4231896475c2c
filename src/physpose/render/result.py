"""Opening a result folder for the outputs, and picking which of its motions to use."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from physpose.errors import PhysposeError
from physpose.reconstruction import MOTIONS, Reconstruction

_RESULT_REMEDY = "pass the folder written by `physpose reconstruct` (it holds reconstruction.npz)"


def load_result(result: str | Path) -> tuple[Reconstruction, Path]:
    """Load reconstruction.npz from a result folder (or the file itself); returns it and the folder."""
    path = Path(result)
    if not path.exists():
        raise PhysposeError("result folder not found", path=path, remedy=_RESULT_REMEDY)
    if path.is_dir() and not Reconstruction.file_in(path).is_file():
        raise PhysposeError("this folder holds no reconstruction.npz", path=path,
                            remedy=_RESULT_REMEDY)
    rec = Reconstruction.load(path)
    return rec, path if path.is_dir() else path.parent


def available_motions(rec: Reconstruction) -> tuple[str, ...]:
    """The motions a result holds as joints: kinematic always, physics when simulated."""
    return MOTIONS if rec.has_physics else ("kinematic",)


def pick_motion(rec: Reconstruction, motion: str | None, source: Path | None = None) -> str:
    """Resolve None to the best motion (physics if present); reject one the result lacks."""
    if motion is None:
        return "physics" if rec.has_physics else "kinematic"
    if motion not in MOTIONS:
        raise PhysposeError(f"unknown motion {motion!r}",
                            remedy=f"choose one of {', '.join(MOTIONS)}")
    if motion == "physics" and not rec.has_physics:
        raise PhysposeError("this result has no physics motion (it is kinematic only)",
                            path=source, remedy="run `physpose reconstruct` to simulate it, or "
                                                "ask for the kinematic motion")
    return motion


def joints_of(rec: Reconstruction, motion: str) -> np.ndarray:
    """(T, J, 3) world joint positions of 'kinematic' or 'physics'."""
    return rec.joints_kinematic if motion == "kinematic" else rec.joints("physics")
