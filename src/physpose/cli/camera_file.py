"""Camera calibration files given on the command line (`--camera`, `--camera-name`): a JSON or
text file of the intrinsics K, or one camera of a Qualisys .qca.txt calibration."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from physpose.errors import PhysposeError
from physpose.keypoints_io import is_keypoints_file, load_keypoints
from physpose.kinematics.camera import check_intrinsics
from physpose.video import probe


def read_intrinsics(path: Path) -> np.ndarray:
    """K (3, 3) from a JSON file ({"K": ...} or the bare matrix) or a text file of 9 numbers
    (camera_intrinsics sends a Qualisys calibration elsewhere)."""
    if not path.is_file():
        raise PhysposeError("camera file not found", path=path, remedy="check the path")
    try:
        if path.suffix.lower() == ".json":
            doc = json.loads(path.read_text())
            K = np.asarray(doc["K"] if isinstance(doc, dict) else doc, dtype=float)
        else:
            K = np.loadtxt(path, dtype=float)
    except (ValueError, KeyError, TypeError, OSError) as exc:
        raise PhysposeError(f"cannot read camera intrinsics ({exc})", path=path,
                            remedy='write {"K": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]}') from None
    return check_intrinsics(K.reshape(3, 3) if K.size == 9 else K, str(path))


def given_intrinsics(path: Path | None, name: str | None, video: Path,
                     image_size: tuple[int, int] | None = None) -> np.ndarray | None:
    """K (3, 3) of --camera (and --camera-name) for the input `video` (a video or keypoints
    file; its image size read where a calibration needs it and `image_size` is not given),
    None without --camera; --camera-name alone is refused rather than ignored."""
    if path is None:
        if name is not None:
            raise PhysposeError("--camera-name chooses a camera of the --camera calibration",
                                remedy="give the Qualisys .qca.txt file with --camera")
        return None
    if image_size is None and _is_qualisys(path):
        image_size = (load_keypoints(video) if is_keypoints_file(video) else probe(video)
                      ).image_size
    return camera_intrinsics(path, name, video, image_size)


def _is_qualisys(path: Path) -> bool:
    return path.name.lower().endswith((".qca.txt", ".qca"))


def camera_intrinsics(path: Path, name: str | None, video: Path,
                      image_size: tuple[int, int] | None) -> np.ndarray:
    """K (3, 3) from a Qualisys .qca.txt (one camera of it, scaled to the input's image_size)
    or a JSON/text intrinsics file; `video` is the input (its name may name the camera)."""
    if not _is_qualisys(path):
        if name is not None:
            raise PhysposeError("--camera-name applies to a Qualisys .qca.txt calibration",
                                path=path, remedy="drop --camera-name")
        return read_intrinsics(path)
    from physpose.multiview.qualisys import load_qualisys  # noqa: PLC0415

    cameras = load_qualisys(path)
    listing = ", ".join(f"{c.name} ({c.image_size[0]}x{c.image_size[1]})" for c in cameras)
    if name is not None:
        chosen = [c for c in cameras if c.name == name]
        if not chosen:
            raise PhysposeError(f"no camera named {name!r}; the file has {listing}", path=path,
                                remedy="pass one of those names to --camera-name")
    else:
        chosen = cameras
        if image_size is not None:
            chosen = [c for c in cameras if _fits(c, image_size)]
        if len(chosen) > 1:
            chosen = [c for c in chosen if c.name.lower() in video.stem.lower()]
        if len(chosen) != 1:
            raise PhysposeError(f"cannot tell which camera filmed {video.name}; the file has "
                                f"{listing}", path=path,
                                remedy="choose one with --camera-name NAME")
    camera = chosen[0]
    if image_size is not None:
        camera = camera.for_image_size(*image_size, source=video)
    return camera.K


def _fits(camera, image_size: tuple[int, int]) -> bool:
    try:
        camera.for_image_size(*image_size)
    except PhysposeError:
        return False
    return True
