"""Motion-capture ground truth: BVH, ASF/AMC and DeepMimic clips as `MocapClip`s.

Every reader returns joints under `physpose.joints.JOINT_NAMES` in the project's world frame
(metres, z up, floor at z = 0), resampled to a target rate. `load_mocap` picks the reader from
the file extension.
"""

from __future__ import annotations

from pathlib import Path

from physpose.errors import PhysposeError
from physpose.mocap.asf_amc import load_amc
from physpose.mocap.bvh import load_bvh
from physpose.mocap.common import (
    BONES,
    MocapClip,
    body_height,
    bone_lengths,
    stance_foot_heights,
)
from physpose.mocap.deepmimic import load_deepmimic

__all__ = [
    "BONES",
    "MOCAP_SUFFIXES",
    "MocapClip",
    "body_height",
    "bone_lengths",
    "load_amc",
    "load_bvh",
    "load_deepmimic",
    "load_mocap",
    "stance_foot_heights",
]

MOCAP_SUFFIXES = (".bvh", ".amc", ".txt", ".json")  # .txt/.json: DeepMimic clips


def load_mocap(path: str | Path, target_fps: float | None = 25.0,
               asf: str | Path | None = None) -> MocapClip:
    """Read a BVH, AMC (skeleton: `asf`, or found beside it) or DeepMimic clip.

    target_fps: rate of the returned clip (None keeps the file's own).
    """
    path = Path(path)
    if not path.is_file():
        raise PhysposeError("motion-capture file not found", path=path)
    suffix = path.suffix.lower()
    if suffix == ".bvh":
        return load_bvh(path, target_fps)
    if suffix == ".amc":
        return load_amc(path, target_fps, asf=asf)
    if suffix in (".txt", ".json"):
        return load_deepmimic(path, target_fps)
    raise PhysposeError(f"unknown motion-capture format {suffix!r}", path=path,
                        remedy="use a .bvh, .amc (with its .asf) or DeepMimic .txt clip")
