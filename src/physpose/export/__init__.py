"""Exports of a result folder: BVH, glTF binary, CSV and JSON joint tables, the forces table."""

from __future__ import annotations

import os
from pathlib import Path

from physpose.cache import atomic_path
from physpose.errors import PhysposeError, expect_type
from physpose.export.bvh import write_bvh
from physpose.export.gltf import write_glb
from physpose.export.table import frame_flags, write_csv, write_forces_csv, write_json
from physpose.render.bodymotion import reconstruction_motion
from physpose.render.result import available_motions, load_result, pick_motion

FORMATS = ("bvh", "glb", "csv", "json", "forces")
# Default file name inside the result folder, per format.
DEFAULT_NAMES = {"bvh": "motion.bvh", "glb": "motion.glb", "csv": "joints.csv",
                 "json": "joints.json", "forces": "forces.csv"}

__all__ = ["FORMATS", "export"]


def export(result_dir: str | Path, fmt: str, out: str | Path | None = None,
           motion: str | None = None) -> Path:
    """Export a result folder to `fmt` (bvh, glb, csv, json, forces); returns the written file.

    motion: 'physics' or 'kinematic'. None means the physics motion if the result has one, else
    the kinematic one, for bvh/glb; and every motion the result holds, for csv/json. forces:
    the physics motion's ground reaction forces and joint torques (no other motion has them).
    """
    if fmt not in FORMATS:
        raise PhysposeError(f"unknown export format {fmt!r}",
                            remedy=f"choose one of {', '.join(FORMATS)}")
    expect_type(result_dir, (str, os.PathLike), "export's result", "pass the result folder (a "
                "Reconstruction in memory: save it into one first, rec.save(folder / "
                "'reconstruction.npz'))")
    rec, folder = load_result(result_dir)
    out = _target(folder, fmt, out)
    if fmt == "forces" and motion == "kinematic":
        raise PhysposeError("only the physics motion has forces", path=folder,
                            remedy="export forces without --motion kinematic")
    body = None
    if fmt in ("bvh", "glb"):
        which = pick_motion(rec, motion, folder)
        body = reconstruction_motion(rec, which)
        if body is None:
            raise PhysposeError(f"this result stores no body model and {which} qpos, which "
                                f"{fmt} export needs", path=folder,
                                remedy="export csv or json, or re-run the reconstruction")
    with atomic_path(out) as tmp:  # a failed write (a full disk) leaves no half file
        if fmt == "forces":
            write_forces_csv(rec, tmp)
        elif fmt in ("csv", "json"):
            motions = (available_motions(rec) if motion is None
                       else (pick_motion(rec, motion, folder),))
            (write_csv if fmt == "csv" else write_json)(rec, motions, tmp)
        elif fmt == "bvh":  # BVH has no place for per-frame data: joints.csv carries the flags
            write_bvh(body, rec.fps, tmp)
        else:
            write_glb(body, rec.fps, tmp, frame_flags(rec, physics=which == "physics"))
    return out


def _target(folder: Path, fmt: str, out: str | Path | None) -> Path:
    """The file to write: the format's default name in ``out`` when it is a folder (or ends in
    a separator: then made), else ``out`` itself, which must carry the format's suffix (an
    export had been written over reconstruction.npz, and glTF bytes into a .bvh)."""
    name = DEFAULT_NAMES[fmt]
    if out is None:
        return folder / name
    if str(out).endswith(("/", os.sep)) or Path(out).is_dir():
        Path(out).mkdir(parents=True, exist_ok=True)
        return Path(out) / name
    out = Path(out)
    suffix = Path(name).suffix
    if out.suffix.lower() != suffix:
        raise PhysposeError(f"{fmt} export to a file that does not end in {suffix}", path=out,
                            remedy=f"name a {suffix} file, or a folder (ending in /) to write "
                                   f"{name} into")
    return out
