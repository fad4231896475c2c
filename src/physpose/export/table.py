"""Plain tables: joint positions as CSV (one row per frame, motion and joint) and JSON, and the
simulation's forces as CSV (one row per frame)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from physpose.errors import PhysposeError
from physpose.json_text import strict_json
from physpose.reconstruction import GRF_PARTS, Reconstruction
from physpose.render.result import joints_of
from physpose.skeleton import DOF_NAMES

# After the joint: where the frame lies in the source video (its frame, seconds into it: what
# --start and --end take), then how far to trust it (FLAG_COLUMNS). Appended in that order as
# they came, so tables read by column number before keep their columns.
VIDEO_COLUMNS = ("video_frame", "video_time")
# detected: 1 where the detector saw the person, 0 where the motion is inferred from the frames
# around (a short gap filled at observe time, or a longer one); physics_restart: 1 where the
# physics motion restarts from the kinematic estimate (it jumps there); physics_invalid: 1 in
# windows where no simulated sample stayed valid. The two physics cells are empty on kinematic
# rows and for results without physics, physics_invalid also where the result does not say.
FLAG_COLUMNS = ("detected", "physics_restart", "physics_invalid")
CSV_COLUMNS = ("frame", "time", "motion", "joint", "x", "y", "z", *VIDEO_COLUMNS, *FLAG_COLUMNS)
_DECIMALS = 6  # metres: micrometre resolution


def frame_flags(rec: Reconstruction, physics: bool) -> dict[str, list[bool] | None]:
    """The FLAG_COLUMNS per frame as lists of true/false: None for the physics flags when
    `physics` is false or the result has no physics, and for physics_invalid where the result
    does not record it."""
    physics = physics and rec.has_physics
    invalid = rec.invalid_physics
    return {"detected": rec.detected.tolist(),
            "physics_restart": rec.restart_flags.tolist() if physics else None,
            "physics_invalid": invalid.tolist() if physics and invalid is not None else None}


def _frame_cells(rec: Reconstruction, physics: bool) -> list[tuple[str, ...]]:
    """Per frame, the VIDEO_COLUMNS and FLAG_COLUMNS cells (empty where the result does not
    record them; the physics flags only for `physics` rows of a result with physics)."""
    frames, times = rec.video_frames, rec.video_times
    by_name = frame_flags(rec, physics)
    flags = [by_name[name] for name in FLAG_COLUMNS]
    return [("" if frames is None else str(int(frames[t])),
             "" if times is None else f"{times[t]:.6f}",
             *("" if flag is None else str(int(flag[t])) for flag in flags))
            for t in range(rec.num_frames)]


def write_csv(rec: Reconstruction, motions: tuple[str, ...], path: str | Path) -> Path:
    """Write frame, time (s from the first frame), motion, joint, x, y, z (m, world z up),
    video_frame, video_time (s into the footage) and the FLAG_COLUMNS for each motion; returns
    path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    times = np.arange(rec.num_frames) / rec.fps
    with path.open("w", newline="") as f:
        out = csv.writer(f)
        out.writerow(CSV_COLUMNS)
        for motion in motions:
            joints = joints_of(rec, motion)
            cells = _frame_cells(rec, physics=motion == "physics")
            for t in range(rec.num_frames):
                for j, name in enumerate(rec.joint_names):
                    x, y, z = (f"{v:.{_DECIMALS}f}" if np.isfinite(v) else ""
                               for v in joints[t, j])  # a lost joint: empty, as in forces.csv
                    out.writerow((t, f"{times[t]:.6f}", motion, name, x, y, z, *cells[t]))
    return path


def write_json(rec: Reconstruction, motions: tuple[str, ...], path: str | Path) -> Path:
    """Write {fps, units, axes, joint_names, time, video_frames, video_times, detected,
    physics_restart, physics_invalid, motions: {name: (T, J, 3) nested lists}}; video_frames
    and video_times null where not recorded, the per-frame flags (FLAG_COLUMNS) true/false,
    the physics ones null without physics."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    frames, times = rec.video_frames, rec.video_times
    doc = {
        "fps": rec.fps, "units": "m", "axes": "world: z up, ground plane z = 0",
        "joint_names": list(rec.joint_names),
        "time": np.round(np.arange(rec.num_frames) / rec.fps, 6).tolist(),
        "video_frames": None if frames is None else frames.tolist(),
        "video_times": None if times is None else np.round(times, 6).tolist(),
        **frame_flags(rec, physics=True),
        "motions": {m: np.round(joints_of(rec, m), _DECIMALS).tolist() for m in motions},
    }
    path.write_text(strict_json(doc, separators=(",", ":")))  # a lost joint as null
    return path


def forces_columns() -> tuple[str, ...]:
    """Columns of the forces table: frame, time (s), the force on each of GRF_PARTS (N, world
    axes), the centre of pressure under each foot (m), the torque across each hinge (N m),
    then VIDEO_COLUMNS and FLAG_COLUMNS (as in CSV_COLUMNS)."""
    grf = [f"{part}_f{axis}_n" for part in GRF_PARTS for axis in "xyz"]
    cop = [f"{side}_cop_{axis}_m" for side in ("l", "r") for axis in "xyz"]
    return ("frame", "time", *grf, *cop, *(f"{name}_torque_nm" for name in DOF_NAMES),
            *VIDEO_COLUMNS, *FLAG_COLUMNS)


def write_forces_csv(rec: Reconstruction, path: str | Path) -> Path:
    """Write the physics motion's forces (reconstruction.npz's grf_physics, cop_physics,
    torques_physics), one row per frame; a centre of pressure under a foot that carries no
    weight, or a force not recorded, is an empty cell. Returns the path."""
    if rec.grf_physics is None or rec.cop_physics is None or rec.torques_physics is None:
        raise PhysposeError("this result holds no simulated forces",
                            remedy="run `physpose reconstruct` (physpose fit writes no physics; "
                                   "results from before physpose recorded forces need a re-run)")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    values = np.concatenate([rec.grf_physics.reshape(rec.num_frames, -1),
                             rec.cop_physics.reshape(rec.num_frames, -1),
                             rec.torques_physics], axis=1)
    times = np.arange(rec.num_frames) / rec.fps
    cells = _frame_cells(rec, physics=True)
    with path.open("w", newline="") as f:
        out = csv.writer(f)
        out.writerow(forces_columns())
        for t, row in enumerate(values):
            out.writerow((t, f"{times[t]:.6f}",
                          *(f"{v:.{_DECIMALS}f}" if np.isfinite(v) else "" for v in row),
                          *cells[t]))
    return path
