"""Joint positions as plain tables: CSV (one row per frame, motion and joint) and JSON."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from physpose.reconstruction import Reconstruction
from physpose.render.result import joints_of

CSV_COLUMNS = ("frame", "time", "motion", "joint", "x", "y", "z")
_DECIMALS = 6  # metres: micrometre resolution


def write_csv(rec: Reconstruction, motions: tuple[str, ...], path: str | Path) -> Path:
    """Write frame, time (s), motion, joint, x, y, z (m, world z up) for each motion; returns path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    times = np.arange(rec.num_frames) / rec.fps
    with path.open("w", newline="") as f:
        out = csv.writer(f)
        out.writerow(CSV_COLUMNS)
        for motion in motions:
            joints = joints_of(rec, motion)
            for t in range(rec.num_frames):
                for j, name in enumerate(rec.joint_names):
                    x, y, z = (f"{v:.{_DECIMALS}f}" for v in joints[t, j])
                    out.writerow((t, f"{times[t]:.6f}", motion, name, x, y, z))
    return path


def write_json(rec: Reconstruction, motions: tuple[str, ...], path: str | Path) -> Path:
    """Write {fps, units, axes, joint_names, time, motions: {name: (T, J, 3) nested lists}}."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    doc = {
        "fps": rec.fps, "units": "m", "axes": "world: z up, ground plane z = 0",
        "joint_names": list(rec.joint_names),
        "time": np.round(np.arange(rec.num_frames) / rec.fps, 6).tolist(),
        "motions": {m: np.round(joints_of(rec, m), _DECIMALS).tolist() for m in motions},
    }
    path.write_text(json.dumps(doc, separators=(",", ":")))
    return path
