"""Precomputed keypoints (the second way in): JSON or npz files -> Observations, and back.

The format is documented in docs/keypoints_format.md. The npz variant uses the same key names
as `observations.npz`, so an observations file is also a valid keypoints file.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from physpose.cache import UNREADABLE_NPZ, atomic_path, npz_arrays
from physpose.errors import PhysposeError, about
from physpose.joints import LANDMARK_NAMES, NUM_LANDMARKS
from physpose.json_text import read_json_file
from physpose.observations import CAMERA_MOTIONS, SURE_CONFIDENCE, Observations

KEYPOINTS_EXTENSIONS = (".json", ".npz")
_DOC = "see docs/keypoints_format.md"
_REQUIRED = ("fps", "image_size", "keypoints2d")
_OPTIONAL = ("world_landmarks", "camera_K", "timestamps", "detected", "interpolated",
             "frame_indices", "masks", "source", "landmark_names", "format_version", "format",
             "homographies", "camera_motion", "unsure")


def is_keypoints_file(path: str | Path) -> bool:
    """True if the extension says precomputed keypoints (.json or .npz)."""
    return Path(path).suffix.lower() in KEYPOINTS_EXTENSIONS


def load_keypoints(path: str | Path) -> Observations:
    """Read a keypoints .json or .npz file into Observations, with errors naming file and frame."""
    path = Path(path)
    if not path.is_file():
        raise PhysposeError("keypoints file not found", path=path, remedy="check the path")
    ext = path.suffix.lower()
    if ext == ".json":
        return _to_observations(_read_json(path), path)
    if ext == ".npz":
        return load_keypoints_npz(path)
    raise PhysposeError(f"unknown keypoints extension '{ext}'", path=path,
                        remedy="use .json or .npz (" + _DOC + ")")


def load_keypoints_npz(path: str | Path) -> Observations:
    """Read a keypoints npz file whatever its name ends with (`Observations.save` writes to
    exactly the path it is given)."""
    path = Path(path)
    return _to_observations(_read_npz(path), path)


def save_keypoints(obs: Observations, path: str | Path) -> Path:
    """Write Observations as a keypoints file, JSON or npz by the extension; atomic."""
    path = Path(path)
    ext = path.suffix.lower()
    if ext == ".npz":
        return obs.save(path)
    if ext != ".json":
        raise PhysposeError(f"unknown keypoints extension '{ext}'", path=path,
                            remedy="use .json or .npz")
    doc: dict[str, Any] = {
        "format": "physpose-keypoints", "format_version": 1, "source": obs.source,
        "landmark_names": list(LANDMARK_NAMES), "fps": float(obs.fps),
        "image_size": [int(v) for v in obs.image_size],
    }
    for key in ("timestamps", "keypoints2d", "detected", "interpolated", "world_landmarks",
                "camera_K", "frame_indices", "homographies", "unsure"):
        value = getattr(obs, key)
        if value is not None:
            doc[key] = np.asarray(value).tolist()
    if obs.camera_motion is not None:
        doc["camera_motion"] = obs.camera_motion
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(doc, allow_nan=False))
    return path


def _read_json(path: Path) -> dict[str, Any]:
    doc = read_json_file(path, remedy="fix the file; " + _DOC)
    if not isinstance(doc, dict):
        raise PhysposeError("the JSON top level must be an object with keys "
                            + ", ".join(_REQUIRED), path=path, remedy=_DOC)
    return doc


def _read_npz(path: Path) -> dict[str, Any]:
    try:
        return npz_arrays(path)
    except UNREADABLE_NPZ as exc:
        raise PhysposeError(f"not a readable npz file ({exc})", path=path,
                            remedy="write it with numpy.savez (no object arrays); " + _DOC) from None


def _homographies(raw: dict[str, Any], kp: np.ndarray, seen: np.ndarray, fail
                  ) -> np.ndarray | None:
    """The (T, 3, 3) camera maps, if given: finite, invertible, and keeping every keypoint of
    a frame with landmarks (`seen`) in front of the camera, as map_keypoints maps them."""
    if raw.get("homographies") is None:
        return None
    t = len(kp)
    maps = _array(raw["homographies"], "homographies", fail)
    if maps.shape != (t, 3, 3) or not np.isfinite(maps).all():
        fail(f"homographies has shape {maps.shape} or non-finite values, expected "
             f"({t}, 3, 3)", "give one 3x3 map per frame, or leave homographies out")
    xy1 = np.concatenate([kp[..., :2], np.ones((t, NUM_LANDMARKS, 1))], axis=-1)
    w = np.einsum("tj,tnj->tn", maps[:, 2], xy1)
    bad = (np.abs(np.linalg.det(maps)) < 1e-12) | (seen & ~(w > 1e-9).all(axis=1))
    if bad.any():
        fail("a homography is singular or maps a keypoint to infinity",
             "give each frame an invertible map of the middle frame's pixels to its own",
             int(np.argmax(bad)))
    return maps


def _masks(raw: dict[str, Any], fail) -> np.ndarray | None:
    """The person masks, if given: a rectangular array of numbers 0-255."""
    if raw.get("masks") is None:
        return None
    try:
        masks = np.asarray(raw["masks"])
    except ValueError:
        fail("masks is not a rectangular array", "give masks as (T, h, w) uint8, or leave "
             "them out")
    if masks.dtype.kind not in "biuf" or not np.isfinite(masks).all() \
            or masks.min(initial=0) < 0 or masks.max(initial=0) > 255:
        fail("masks must hold numbers 0-255 (person probability x 255)",
             "give masks as (T, h, w) uint8, or leave them out")
    return masks


def _to_observations(raw: dict[str, Any], path: Path) -> Observations:
    def fail(problem: str, remedy: str, frame: int | None = None) -> None:
        raise PhysposeError(problem, path=path, frame=frame, remedy=remedy + " (" + _DOC + ")")

    missing = [k for k in _REQUIRED if k not in raw]
    if missing:
        fail(f"missing required key(s) {', '.join(missing)}",
             f"add {', '.join(missing)}; required keys are {', '.join(_REQUIRED)}")
    unknown = sorted(set(raw) - set(_REQUIRED) - set(_OPTIONAL))
    if unknown:
        fail(f"unknown key(s) {', '.join(unknown)}", "remove them or fix their spelling")
    if "landmark_names" in raw and [str(n) for n in np.asarray(raw["landmark_names"]).ravel()] \
            != list(LANDMARK_NAMES):
        fail("landmark_names differ from MediaPipe's 33-landmark order",
             "reorder the keypoints to MediaPipe Pose order")

    fmt, version = (raw.get(k) for k in ("format", "format_version"))
    fmt, version = (None if v is None else np.asarray(v).tolist() for v in (fmt, version))
    if fmt not in (None, "physpose-keypoints") or version not in (None, 1):
        fail(f"format {fmt!r} version {version!r} is not "
             "physpose-keypoints version 1", "leave format and format_version out, or write "
             "\"physpose-keypoints\" and 1")
    fps = _number(raw["fps"])
    if fps is None or not (math.isfinite(fps) and 0.5 <= fps <= 1000):
        fail(f"fps {raw['fps']!r} is not a frame rate in 0.5-1000 Hz",
             "set fps to the rate of the keypoints, e.g. 25")
    size = _array(raw["image_size"], "image_size", fail)
    if size.shape != (2,) or not np.all(np.isfinite(size)) or np.any(size <= 0) \
            or np.any(size != np.round(size)):
        fail(f"image_size {size.tolist()} must be [width, height] in positive whole pixels",
             "set image_size to the video's frame size")

    kp = _array(raw["keypoints2d"], "keypoints2d", fail)
    if kp.ndim != 3 or kp.shape[1:] != (NUM_LANDMARKS, 3) or kp.shape[0] == 0:
        fail(f"keypoints2d has shape {kp.shape}, expected (T, {NUM_LANDMARKS}, 3) with T >= 1",
             "store per frame 33 MediaPipe-order rows of (x px, y px, confidence)")
    t = kp.shape[0]
    _check_finite(kp, "keypoints2d", fail,
                  "mark a missing keypoint with confidence 0 and finite coordinates, not NaN")
    conf = kp[..., 2]
    out = (conf < 0) | (conf > 1)
    if out.any():
        f = int(np.argmax(out.any(axis=1)))
        fail(f"keypoint confidence {conf[f][out[f]][0]:g} is outside [0, 1]",
             "scale confidences to [0, 1]", f)
    # A joint the detector is sure of lies in the picture or near it, never a whole picture
    # away (MediaPipe guesses joints out of view far away, but with a visibility near 0).
    # Keypoints mapped into the middle frame's image of a turning camera (homographies) can lie
    # anywhere a wide pan reaches, so they are not held to this.
    far = (conf >= SURE_CONFIDENCE) & ((kp[..., 0] < -size[0]) | (kp[..., 0] > 2 * size[0])
                                       | (kp[..., 1] < -size[1]) | (kp[..., 1] > 2 * size[1]))
    far &= raw.get("homographies") is None
    if far.any():
        f = int(np.argmax(far.any(axis=1)))
        x, y = kp[f][far[f]][0, :2]
        fail(f"a keypoint of confidence {SURE_CONFIDENCE:g} or more lies at ({x:g}, {y:g}) px, "
             f"more than a picture away from the {int(size[0])}x{int(size[1])} image",
             "give x and y in pixels of the video's frames (origin top left), and a low "
             "confidence to a keypoint that was guessed", f)

    per_frame: dict[str, np.ndarray | None] = {}
    for key, shape in (("world_landmarks", (t, NUM_LANDMARKS, 3)), ("timestamps", (t,)),
                       ("detected", (t,)), ("interpolated", (t,)), ("frame_indices", (t,)),
                       ("unsure", (t,))):
        value = None if raw.get(key) is None else _array(raw[key], key, fail)
        if value is not None:
            if value.shape != shape:
                fail(f"{key} has shape {value.shape}, expected {shape} (T = {t} frames from "
                     "keypoints2d)", f"give {key} one entry per frame")
            _check_finite(value, key, fail, f"replace non-finite {key} values")
        per_frame[key] = value
    ts = per_frame["timestamps"]
    if ts is None:
        ts = np.arange(t) / fps
    elif t > 1 and np.any(np.diff(ts) <= 0):
        fail("timestamps are not strictly increasing",
             "give one increasing time in seconds per frame", int(np.argmax(np.diff(ts) <= 0)) + 1)
    elif t > 1 and min(abs(step * fps - 1) for step in (
            float(np.median(np.diff(ts))), (ts[-1] - ts[0]) / (t - 1))) > 0.25:
        # the mean step too: frames picked from a 30 fps video at 20 fps are 1 and 2 source
        # frames apart (video.plan_frames), whose median is 15 or 30 frames a second
        fail(f"timestamps are {(t - 1) / (ts[-1] - ts[0]):g} frames a second, fps says "
             f"{fps:g}", "make fps the rate of the frames, or leave timestamps out")
    detected = per_frame["detected"]
    detected = (conf > 0).any(axis=1) if detected is None else detected.astype(bool)
    interpolated = per_frame["interpolated"]
    interpolated = np.zeros(t, bool) if interpolated is None else interpolated.astype(bool)

    camera_k = None if raw.get("camera_K") is None else _array(raw["camera_K"], "camera_K", fail)
    if camera_k is not None and (camera_k.shape != (3, 3) or not np.isfinite(camera_k).all()):
        fail(f"camera_K has shape {camera_k.shape} or non-finite values, expected a finite "
             "3x3 matrix", "give the intrinsics [[fx,0,cx],[0,fy,cy],[0,0,1]] in pixels")
    if camera_k is not None and (camera_k[0, 0] <= 0 or camera_k[1, 1] <= 0
                                 or not np.allclose(camera_k[2], [0, 0, 1])):
        fail(f"camera_K {camera_k.tolist()} is not a pinhole matrix (fx, fy > 0, last row "
             "0 0 1)", "give the intrinsics [[fx,0,cx],[0,fy,cy],[0,0,1]] in pixels")
    homographies = _homographies(raw, kp, detected | interpolated, fail)
    motion = raw.get("camera_motion")
    motion = None if motion is None else str(np.asarray(motion))
    if motion is not None and motion not in CAMERA_MOTIONS:
        fail(f"camera_motion {motion!r} is not one of {', '.join(CAMERA_MOTIONS)}",
             "leave camera_motion out, or write what `physpose observe` wrote")
    masks = _masks(raw, fail)
    source = raw.get("source")
    recorded = str(path) if source is None else str(np.asarray(source))
    with about(path, instead_of=recorded):  # the checks name the recorded video, not this file
        return Observations(
            source=recorded, fps=float(fps), image_size=(int(size[0]), int(size[1])),
            timestamps=ts.astype(float), keypoints2d=kp, detected=detected,
            interpolated=interpolated, world_landmarks=per_frame["world_landmarks"],
            masks=masks, camera_K=camera_k,
            frame_indices=None if per_frame["frame_indices"] is None
            else per_frame["frame_indices"].astype(np.int64),
            homographies=homographies, camera_motion=motion,
            unsure=None if per_frame["unsure"] is None else per_frame["unsure"].astype(bool))


def _number(value: Any) -> float | None:
    arr = np.asarray(value)
    if arr.shape != () or arr.dtype.kind not in "iuf":
        return None
    return float(arr)


def _array(value: Any, key: str, fail) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        fail(f"{key} is not a rectangular array of numbers (ragged lists, nulls or strings)",
             f"give {key} the same number of entries in every frame, numbers only")
    return arr


def _check_finite(arr: np.ndarray, key: str, fail, remedy: str) -> None:
    bad = ~np.isfinite(arr)
    if bad.any():
        frame = int(np.argmax(bad.reshape(len(arr), -1).any(axis=1))) if arr.ndim else None
        fail(f"{key} contains NaN or infinite values", remedy, frame)
