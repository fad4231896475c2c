"""Benchmark material turned into clips: observations for a variant plus what scores it.

Three kinds: `mocap` (motion capture through the detector simulator; ground truth in a virtual
camera), `multiview` (one clip per view of a calibrated multi-view folder; the triangulated
reference is the truth), `video` (a real video; no 3d truth).
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from physpose.benchmark.variants import VariantContext
from physpose.detector_sim import DetectorSimConfig, simulate_detections
from physpose.errors import PhysposeError
from physpose.mocap import MOCAP_SUFFIXES, MocapClip, body_height, load_mocap
from physpose.joints import joints_from_landmarks
from physpose.multiview.reference import (MultiviewReference, ReferenceConfig,
                                          build_multiview_reference, find_multiview_files,
                                          triangulate_views)
from physpose.observations import Observations
from physpose.observe import ObserveConfig, observe
from physpose.paths import pose2sim_demo_dir, shared_data_dir
from physpose.video import VIDEO_EXTENSIONS, probe

KINDS = ("mocap", "multiview", "video")
CAMERA_HEIGHT_RANGE = (0.1, 20.0)  # m, mocap's virtual camera above the floor
MAX_SLOW_MOTION = 16  # the slowest footage the benchmark plays motion capture as (x real time)
# What a multi-view folder's views are scored against: the reference triangulated from every
# view, or for each view the one triangulated from the other views (leave one out).
MULTIVIEW_TRUTHS = ("all-views", "other-views")


@dataclass(frozen=True)
class MaterialConfig:
    """How material is cut and observed for the benchmark."""

    fps: float = 25.0             # Hz, target analysis rate (the paper's)
    max_seconds: float = 4.0      # s, clip length cap (the paper's clips are 100 frames at 25 Hz)
    start_seconds: float = 0.0    # s, where each clip begins (later segments: held-out material)
    camera_azimuth_deg: float = DetectorSimConfig.azimuth_deg  # mocap's camera, deg (0: in front)
    camera_height: float = DetectorSimConfig.height  # m, mocap's camera above the floor
    known_intrinsics: bool = True   # tell variants the camera K when the material has one
    known_extrinsics: bool = False  # tell variants the camera pose (then ground is not scored)
    known_height: bool = False    # tell variants the person's stature when the material has it
    seed: int = 0                 # detector simulator seed
    noiseless: bool = False       # mocap seen by a detector without noise or biases (an oracle)
    truth_input: bool = False     # give variants the mocap truth (an oracle, benchmark/oracle.py)
    # Motion capture filmed this many times slower than it happened and not declared: the
    # detector simulator sees it at fps x slow_motion, the footage plays at fps, and every
    # slow_motion-th frame is scored on the real clock (what users who do not pass
    # --slow-motion get; docs/benchmark.md). Motion capture only.
    slow_motion: int = 1
    # Multi-view folders: "all-views" scores each view against the reference triangulated from
    # every view, its own detections included, which pull that reference towards themselves
    # (an estimate that stays near the view's detections is favoured); "other-views" against
    # the reference triangulated without the scored view (unbiased by it, but noisier: fewer
    # views, and on the pose2sim demo more of cam02's left/right swaps). docs/benchmark.md.
    multiview_truth: str = "all-views"

    def __post_init__(self) -> None:
        if self.multiview_truth not in MULTIVIEW_TRUTHS:
            raise PhysposeError(f"multiview_truth={self.multiview_truth!r} is unknown",
                                remedy=f"use one of {', '.join(MULTIVIEW_TRUTHS)}")
        if not (math.isfinite(self.fps) and self.fps > 0):
            raise PhysposeError(f"fps={self.fps} must be > 0", remedy="pass e.g. --fps 25")
        if not (math.isfinite(self.max_seconds) and self.max_seconds > 0):
            raise PhysposeError(f"max_seconds={self.max_seconds} must be > 0",
                                remedy="pass --max-seconds with a positive number of seconds")
        if not (math.isfinite(self.start_seconds) and self.start_seconds >= 0):
            raise PhysposeError(f"start_seconds={self.start_seconds} must be >= 0",
                                remedy="pass --start with a time in seconds, e.g. --start 4")
        if not (isinstance(self.slow_motion, int) and 1 <= self.slow_motion <= MAX_SLOW_MOTION):
            raise PhysposeError(f"slow_motion={self.slow_motion} must be a whole number from 1 "
                                f"to {MAX_SLOW_MOTION}", remedy="pass e.g. --slow-motion 4")
        if not math.isfinite(self.camera_azimuth_deg):
            raise PhysposeError(f"camera_azimuth_deg={self.camera_azimuth_deg} is not a number",
                                remedy="pass --camera-azimuth in degrees, e.g. --camera-azimuth 60")
        low, high = CAMERA_HEIGHT_RANGE
        if not low <= self.camera_height <= high:  # NaN fails too
            raise PhysposeError(f"camera_height={self.camera_height} m is outside {low}-{high} m",
                                remedy="pass --camera-height in metres above the floor, e.g. "
                                       "--camera-height 2.5")


@dataclass(frozen=True, eq=False)
class Truth:
    """Ground truth of a clip, world frame (z up, floor z = 0), and the camera that saw it."""

    joints: np.ndarray         # (T, J, 3) m, JOINT_NAMES order
    T_world2cam: np.ndarray    # (4, 4) OpenCV camera axes
    K: np.ndarray              # (3, 3) px
    dist: np.ndarray = field(default_factory=lambda: np.zeros(5))  # OpenCV k1, k2, p1, p2, k3


@dataclass(frozen=True, eq=False)
class Clip:
    """One benchmark input: what a variant sees and what it is scored against."""

    kind: str                     # one of KINDS
    name: str
    source: str                   # file or folder it came from
    observations: Observations
    context: VariantContext
    truth: Truth | None           # None for real videos
    timings_s: dict[str, float]   # seconds spent producing the observations, per stage
    # Every score_step-th frame is scored, against the truth's frame of the same index: slowed
    # footage's frames on the real clock at the footage's frame rate.
    score_step: int = 1


@dataclass(frozen=True)
class Material:
    """A file or folder to benchmark on."""

    kind: str
    path: Path


def uniform_fps(native: float, target: float) -> float:
    """The rate nearest `target` that samples a `native`-rate source at a fixed frame step."""
    return native / max(1, round(native / target))


def load_clips(material: Material, cfg: MaterialConfig) -> list[Clip]:
    """The clips of one piece of material (one per view for multi-view folders)."""
    loaders = {"mocap": _mocap_clips, "multiview": _multiview_clips, "video": _video_clips}
    if material.kind not in loaders:
        raise ValueError(f"unknown material kind {material.kind!r}")
    if not material.path.exists():
        raise PhysposeError(f"{material.kind} material not found", path=material.path,
                            remedy="check the path")
    if cfg.slow_motion != 1 and material.kind != "mocap":
        raise PhysposeError(f"only motion capture can be played as slow motion; this is "
                            f"{material.kind} material", path=material.path,
                            remedy="leave it out, or drop --slow-motion")
    return loaders[material.kind](material.path, cfg)


def shared_material() -> tuple[list[Material], list[str]]:
    """The shared evaluation material that is present, and a message for each absent part."""
    found: list[Material] = []
    skipped: list[str] = []
    mocap = shared_data_dir() / "mocap"
    files = sorted(p for p in mocap.rglob("*") if _is_mocap_clip(p)) if mocap.is_dir() else []
    found += [Material("mocap", p) for p in files]
    if not files:
        skipped.append(f"no motion capture in {mocap} (see ../shared/data/README.md)")
    videos = shared_data_dir() / "video"
    clips = sorted(p for p in videos.glob("*") if p.suffix.lower() in VIDEO_EXTENSIONS) \
        if videos.is_dir() else []
    found += [Material("video", p) for p in clips]
    if not clips:
        skipped.append(f"no videos in {videos} (see ../shared/data/README.md)")
    demo = pose2sim_demo_dir()
    if (demo / "videos").is_dir() and (demo / "calibration").is_dir():
        found.append(Material("multiview", demo))
    else:
        skipped.append(f"pose2sim demo not found at {demo}; run `make data`")
    return found, skipped


def _is_mocap_clip(path: Path) -> bool:
    """BVH, AMC or DeepMimic motion files (not skeleton-only files such as character_*.txt)."""
    if path.suffix.lower() not in MOCAP_SUFFIXES or not path.is_file():
        return False
    return path.suffix.lower() in (".bvh", ".amc") or not path.name.startswith("character_")


def _clip_end(duration: float, cfg: MaterialConfig) -> float | None:
    end = cfg.start_seconds + cfg.max_seconds
    return None if duration <= end else end


def _observe_config(video: Path, cfg: MaterialConfig) -> ObserveConfig:
    info = probe(video)
    if cfg.start_seconds >= info.duration:
        raise PhysposeError(f"the video is {info.duration:.1f} s long; the benchmark's start "
                            f"{cfg.start_seconds:g} s is past its end", path=video,
                            remedy="pass a smaller --start, or leave this video out")
    return ObserveConfig(target_fps=uniform_fps(info.fps, cfg.fps),
                         start=cfg.start_seconds or None, end=_clip_end(info.duration, cfg))


def _segment_name(name: str, cfg: MaterialConfig) -> str:
    """A clip's name, marked with its start time when it does not begin at 0."""
    return f"{name}@{cfg.start_seconds:g}s" if cfg.start_seconds else name


def _video_clips(path: Path, cfg: MaterialConfig) -> list[Clip]:
    start = time.perf_counter()
    obs = observe(path, _observe_config(path, cfg), progress=False)
    return [Clip(kind="video", name=_segment_name(path.stem, cfg), source=str(path),
                 observations=obs, context=VariantContext(seed=cfg.seed), truth=None,
                 timings_s={"observe": time.perf_counter() - start})]


def _multiview_clips(folder: Path, cfg: MaterialConfig) -> list[Clip]:
    start = time.perf_counter()
    files = find_multiview_files(folder)
    ref_cfg = ReferenceConfig(observe=_observe_config(files.videos[0], cfg))
    ref = build_multiview_reference(folder, ref_cfg)
    elapsed = {"observe+triangulate (all views)": time.perf_counter() - start}
    clips = []
    for view, (cam, obs) in enumerate(zip(ref.cameras, ref.views)):
        context = VariantContext(
            camera_K=cam.K if cfg.known_intrinsics else None,
            camera_T_world2cam=cam.T_world2cam if cfg.known_extrinsics else None, seed=cfg.seed)
        joints = ref.joints if cfg.multiview_truth == "all-views" else \
            _reference_without(ref, view, ref_cfg, folder)
        truth = Truth(joints=joints, T_world2cam=cam.T_world2cam, K=cam.K, dist=cam.dist)
        clips.append(Clip(kind="multiview", name=_segment_name(f"{folder.name}/{cam.name}", cfg),
                          source=str(folder), observations=obs, context=context, truth=truth,
                          timings_s=elapsed))
    return clips


def _reference_without(ref: MultiviewReference, view: int, cfg: ReferenceConfig,
                       folder: Path) -> np.ndarray:
    """(T, J, 3) the joints of the reference triangulated from every view but `view`."""
    arrays = triangulate_views(ref.cameras, ref.views, cfg.triangulation, folder, exclude=view)
    return joints_from_landmarks(arrays["landmarks"])


def _mocap_clips(path: Path, cfg: MaterialConfig) -> list[Clip]:
    start = time.perf_counter()
    motion = load_mocap(path, target_fps=cfg.fps * cfg.slow_motion)
    if motion.meta.get("leading_frames_dropped"):
        print(f"benchmark: {path.name}: its first {motion.meta['leading_frames_dropped']} "
              "frame(s) hold a rest pose joined to the motion by a jump; left out",
              file=sys.stderr, flush=True)
    if cfg.start_seconds and motion.num_frames <= round(cfg.start_seconds * motion.fps) + 1:
        raise PhysposeError(f"the clip is {motion.num_frames / motion.fps:.1f} s long; the "
                            f"benchmark's start {cfg.start_seconds:g} s leaves under two frames",
                            path=path, remedy="pass a smaller --start, or leave this clip out")
    clip = mocap_clip(motion, cfg, name=_segment_name(path.stem, cfg))
    clip.timings_s["load"] = time.perf_counter() - start - clip.timings_s["simulate"]
    return [clip]


def mocap_clip(motion: MocapClip, cfg: MaterialConfig, name: str) -> Clip:
    """A benchmark clip from ground-truth motion: cropped, then seen by the detector simulator.
    With `cfg.slow_motion` X, `motion` is sampled at X times the analysis rate, and its footage
    plays X times slower than the motion happened."""
    start = time.perf_counter()
    motion = crop_mocap(motion, cfg.max_seconds, cfg.start_seconds)
    camera = dict(seed=cfg.seed, azimuth_deg=cfg.camera_azimuth_deg, height=cfg.camera_height)
    detector = DetectorSimConfig.noiseless(**camera) if cfg.noiseless \
        else DetectorSimConfig(**camera)
    capture = simulate_detections(motion, detector)
    context = VariantContext(
        camera_K=capture.camera_K if cfg.known_intrinsics else None,
        camera_T_world2cam=capture.camera_T_world2cam if cfg.known_extrinsics else None,
        person_height=body_height(motion) if cfg.known_height else None, seed=cfg.seed,
        truth_landmarks=capture.landmarks if cfg.truth_input else None,
        truth_T_world2cam=capture.camera_T_world2cam if cfg.truth_input else None)
    truth = Truth(joints=capture.joints, T_world2cam=capture.camera_T_world2cam,
                  K=capture.camera_K)
    obs, step = capture.observations, cfg.slow_motion
    if step != 1:  # captured at fps x step, played at fps: the footage's clock runs slow
        obs = obs.on_real_clock(1.0 / step)  # the inverse of declaring it
    return Clip(kind="mocap", name=name, source=motion.source, observations=obs,
                context=context, truth=truth, score_step=step,
                timings_s={"simulate": time.perf_counter() - start})


def crop_mocap(clip: MocapClip, max_seconds: float, start_seconds: float = 0.0) -> MocapClip:
    """At most `max_seconds` of a clip from `start_seconds` on (at least two frames; a start
    past the end keeps the last two)."""
    first = max(0, min(int(round(start_seconds * clip.fps)), clip.num_frames - 2))
    n = max(2, int(round(max_seconds * clip.fps)))
    if first == 0 and clip.num_frames <= n:
        return clip
    rows = slice(first, first + n)
    return dataclasses.replace(clip, **{k: getattr(clip, k)[rows] for k in
                                        ("joints", "head_top", "head_rot", "hand_rot")})
