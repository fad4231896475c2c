"""The observe stage: video -> per-frame MediaPipe Pose landmarks, world landmarks and masks.

MediaPipe Pose (legacy `mp.solutions.pose`, model_complexity=1, video mode, landmark smoothing
on) runs on frames resampled to `ObserveConfig.target_fps`. Per frame it keeps the 33 image
landmarks (pixels + visibility), the 33 world landmarks and a downsampled person mask.

World landmarks: MediaPipe gives metres with the origin midway between the hips and the axes of
the camera image: x to the right of the image, y down the image, z away from the camera, a
right-handed frame, i.e. OpenCV camera axes without the translation. (Checked on the pose2sim
clip by tests/test_observe.py: world x/y grow with image x/y, and the nose lies in front of the
chest under the right-handed cross product.)

MediaPipe's tracker follows one person and, when it loses that person, takes whichever person
its detector finds next. When the detections jump like that (`diagnostics.person_jumps`), the
video is looked at a second time with every frame masked to where the subject can be (the
longest track and the tracks continuing it; subject.py), and that result is kept if it jumps
less. Videos whose detections do not jump are looked at once. Where the whole picture changes
at once (a cut in an edited video, scene_cuts.py), observe warns with the cut's time and leaves
a gap across it unfilled (`unbridge_cuts`). A user who wants another person than the one
physpose would pick names them by a point on them in the first analysed frame (`person`,
`--person X,Y`): the detector then only ever sees the image around that person's last
detection (subject.Follower), and the automatic second look is skipped.

A person too small for MediaPipe's detector, which sees the whole frame shrunk to a couple of
hundred pixels (under about a third of the image height), is found in none or some frames. When
the first look finds the person in fewer than `min_detection_fraction` of the frames, observe
searches square tiles of a few frames for them (`subject.tiles`) and follows the one found in a
square crop around their last detection, scaled to CROP_SIZE (`detect_in_crop`); landmarks and
masks are mapped back to the whole image. A person the first look found, but small (SMALL_PERSON)
and in fewer than PATCHY of the frames, is followed in the same crops from their first
detection. The crop pass is kept where it finds the person in more frames. The same crops serve
a `person` too small to be found in the whole frame.

A camera that turns while filming (a pan or tilt to follow the person) is measured from the
background (`camera_motion.py`) and the detections are mapped into the middle frame's camera
(`stabilize`, on by default), so the later stages see a still camera; `Observations.homographies`
maps back to each frame's pixels. A camera that also travels is only reported
(`Observations.camera_motion` "moving").

A detection whose person mask is a blurred blob rather than a person's outline (the landmark
model was handed a poor region: glare, a first detection off the person) has torn landmarks;
it is left out (`unsure_mask_band`, mask_quality.py) before the gaps are filled. Where the
first sure detection comes after the clip's first frame, the frames before it are detected
again by a pass running backwards from just after it (`_recover_head`).

Frames without a detection are flagged; gaps of at most `max_gap_frames` between two detected
frames are filled by linear interpolation (positions, confidences, world landmarks and masks)
and flagged `interpolated`. Results are cached (`physpose.cache`) by the video's bytes, the
config and OBSERVE_VERSION, with the warnings the run gave, which a cache hit gives again.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from physpose import native_chatter
from physpose import video as videolib
from physpose.cache import Cache, stage_key
from physpose.camera_motion import estimate_camera_motion, stabilize
from physpose.diagnostics import (image_box_corners, image_boxes, inside_image,
                                  person_jumps)
from physpose.errors import PhysposeError
from physpose.joints import NUM_LANDMARKS
from physpose.mask_quality import band_limit, band_width, unsure_frames
from physpose.observations import Observations
from physpose.scene_cuts import CutFinder, cut_message
from physpose.subject import (Follower, covers, detection_box, mask_outside, seed_regions,
                              square_crop, subject_regions, tiles)

OBSERVE_VERSION = 15  # bump when a change alters what observe() returns for the same input
CROP_SIZE = 512      # px, side of the square crop a small person is followed in (subject.py)
MIN_SEED_VISIBILITY = 0.5  # mean landmark visibility of a detection found in a tile
HEAD_WARMUP = 3            # frames past the first sure detection the backward pass starts at
MAX_HEAD_SECONDS = 2.0     # the longest unseen clip head searched backwards
MAX_HEAD_LONG_SIDE = 1920  # px: larger head frames are shrunk while held for the backward pass
HEAD_VIEW_LOSS = 0.1       # a backward detection may have at most this share fewer landmarks
                           # inside the image than the first sure one (a person leaving view)
_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ObserveConfig:
    """Settings of the observe stage (all but use_cache are part of the cache key)."""

    target_fps: float = 25.0               # Hz; capped at the video's own rate (paper: 25)
    model_complexity: int = 1              # MediaPipe model; only 1 ships in the wheel (offline)
    min_detection_confidence: float = 0.5  # person detector threshold, [0, 1]
    min_tracking_confidence: float = 0.5   # below this the tracker re-detects, [0, 1]
    mask_long_side: int = 256              # px, longer side of the stored mask; 0 = no masks
    max_gap_frames: int = 5                # longest gap filled by interpolation (5 = 0.2 s at 25 Hz)
    unsure_mask_band: float = 3.0          # mask px at a 256-px mask: a detection whose person
                                           # mask's unsure band is wider is left out
                                           # (mask_quality.py); 0 = keep every detection
    follow_back: bool = True               # search an unseen clip head by a backward pass
    min_detection_fraction: float = 0.5    # fail if the person is found in fewer frames than this
    start: float | None = None             # s, first time analysed (None: start of the video)
    end: float | None = None               # s, analysis stops before this (None: end of video)
    person: tuple[float, float] | None = None  # px (x, y): a point on the person to follow in
                                           # the first analysed frame (None: physpose picks)
    stabilize: bool = True                 # map detections into one camera where it turns
    use_cache: bool = True                 # reuse a cached result for the same input and settings

    def __post_init__(self) -> None:
        def bad(problem: str, remedy: str) -> None:
            raise PhysposeError(f"observe config: {problem}", remedy=remedy)

        if self.model_complexity != 1:
            bad(f"model_complexity={self.model_complexity} is not available offline",
                "use model_complexity=1 (mediapipe 0.10.21 ships only that model)")
        for name in ("min_detection_confidence", "min_tracking_confidence",
                     "min_detection_fraction"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0 <= value <= 1):
                bad(f"{name}={value} is outside [0, 1]", f"set {name} between 0 and 1")
        if self.person is not None and (len(self.person) != 2
                                        or not all(math.isfinite(v) for v in self.person)):
            bad(f"person={self.person} is not an image point", "give x,y in pixels")
        if self.mask_long_side < 0 or self.max_gap_frames < 0:
            bad("mask_long_side and max_gap_frames must be >= 0", "use non-negative integers")
        if not (math.isfinite(self.unsure_mask_band) and self.unsure_mask_band >= 0):
            bad(f"unsure_mask_band={self.unsure_mask_band} is not a width",
                "use a non-negative number of mask pixels (0 keeps every detection)")
        videolib.check_target_fps(self.target_fps)


@dataclass(frozen=True)
class FrameDetection:
    """MediaPipe's answer for one frame where it found the person."""

    keypoints2d: np.ndarray        # (33, 3) x, y pixels + visibility in [0, 1]
    world_landmarks: np.ndarray    # (33, 3) m, hip-centred, camera axes
    mask: np.ndarray | None        # (h, w) uint8 person probability x 255, downsampled


class PoseDetector:
    """MediaPipe Pose in video mode for one sequence of frames; use as a context manager.

    Frames must be passed in time order (the legacy API stamps them itself, 33.3 ms apart; the
    stamps only drive landmark smoothing).
    """

    def __init__(self, cfg: ObserveConfig, static: bool = False):
        """static: every frame on its own (no tracking, no smoothing), for single images."""
        import mediapipe as mp  # imported here: loading it costs ~1 s

        self.mask_long_side = cfg.mask_long_side
        # The graph's threads log natively to stderr while it starts and on its first frames.
        self._quiet = contextlib.ExitStack()
        self._quiet.enter_context(native_chatter.filtered())
        try:
            self._pose = mp.solutions.pose.Pose(
                static_image_mode=static, model_complexity=cfg.model_complexity,
                smooth_landmarks=True, enable_segmentation=cfg.mask_long_side > 0,
                smooth_segmentation=True,
                min_detection_confidence=cfg.min_detection_confidence,
                min_tracking_confidence=cfg.min_tracking_confidence)
        except BaseException:
            self._quiet.close()
            raise

    def __enter__(self) -> "PoseDetector":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        try:
            self._pose.close()
        finally:
            self._quiet.close()

    def detect(self, image_bgr: np.ndarray) -> FrameDetection | None:
        """Landmarks of the most prominent person in a BGR image (H, W, 3), or None."""
        height, width = image_bgr.shape[:2]
        rgb = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2RGB)
        rgb.flags.writeable = False
        result = self._pose.process(rgb)
        if result.pose_landmarks is None or result.pose_world_landmarks is None:
            return None
        lm = np.array([(p.x * width, p.y * height, p.visibility)
                       for p in result.pose_landmarks.landmark], dtype=np.float64)
        lm[:, 2] = np.clip(lm[:, 2], 0.0, 1.0)
        world = np.array([(p.x, p.y, p.z) for p in result.pose_world_landmarks.landmark],
                         dtype=np.float64)
        mask = None
        if self.mask_long_side > 0 and result.segmentation_mask is not None:
            mask = downsample_mask(result.segmentation_mask, self.mask_long_side)
        return FrameDetection(keypoints2d=lm, world_landmarks=world, mask=mask)


def mask_shape(image_size: tuple[int, int], long_side: int) -> tuple[int, int]:
    """(h, w) of a mask whose longer side is `long_side` px, for an image of (width, height)."""
    width, height = image_size
    scale = min(1.0, long_side / max(width, height))
    return max(1, round(height * scale)), max(1, round(width * scale))


def downsample_mask(prob: np.ndarray, long_side: int) -> np.ndarray:
    """Person probability (H, W) float in [0, 1] -> (h, w) uint8, area-averaged."""
    h, w = mask_shape((prob.shape[1], prob.shape[0]), long_side)
    small = cv2.resize(prob.astype(np.float32), (w, h), interpolation=cv2.INTER_AREA)
    return np.round(np.clip(small, 0.0, 1.0) * 255).astype(np.uint8)


def detect_in_crop(detector: PoseDetector, image: np.ndarray, box: np.ndarray,
                   mask_size: tuple[int, int] | None = None) -> FrameDetection | None:
    """Detect in the square crop around box [x0, y0, x1, y1] (subject.square_crop), scaled to
    CROP_SIZE; landmarks in image pixels, the mask (if any) on the image's (h, w) mask grid
    `mask_size`, zero outside the crop."""
    crop, origin, scale = square_crop(image, box, CROP_SIZE)
    found = detector.detect(crop)
    if found is None:
        return None
    kp = found.keypoints2d.copy()
    kp[:, :2] = kp[:, :2] * scale + origin
    mask = None
    if found.mask is not None and mask_size is not None:
        height, width = image.shape[:2]
        mh, mw = mask_size
        sx, sy = mw / width, mh / height
        per_px = CROP_SIZE * scale / found.mask.shape[1]   # image px per crop-mask px
        warp = np.array([[per_px * sx, 0.0, origin[0] * sx], [0.0, per_px * sy, origin[1] * sy]])
        mask = cv2.warpAffine(found.mask, warp, (mw, mh), flags=cv2.INTER_AREA,
                              borderValue=0)
    return FrameDetection(keypoints2d=kp, world_landmarks=found.world_landmarks, mask=mask)


def _fill_all_gaps(kp: np.ndarray, world: np.ndarray | None, masks: np.ndarray | None,
                   detected: np.ndarray, max_gap: int) -> tuple:
    """fill_gaps on the landmarks, world landmarks and masks (those given) alike: (kp, world,
    masks, interpolated)."""
    kp, interpolated = fill_gaps(kp, detected, max_gap)
    world = None if world is None else fill_gaps(world, detected, max_gap)[0]
    masks = None if masks is None else fill_gaps(masks, detected, max_gap)[0]
    return kp, world, masks, interpolated


def fill_gaps(values: np.ndarray, detected: np.ndarray, max_gap: int) -> tuple[np.ndarray, np.ndarray]:
    """Linearly interpolate runs of at most `max_gap` undetected frames between detected ones.

    values: (T, ...) per-frame arrays; detected: (T,) bool.
    Returns (filled copy of values, (T,) bool of the frames that were filled). Gaps at either end,
    and longer gaps, are left untouched.
    """
    detected = np.asarray(detected, dtype=bool)
    filled = np.array(values, copy=True)
    interpolated = np.zeros_like(detected)
    hits = np.flatnonzero(detected)
    for a, b in zip(hits[:-1], hits[1:]):
        gap = b - a - 1
        if 0 < gap <= max_gap:
            w = (np.arange(1, gap + 1) / (gap + 1)).reshape((-1,) + (1,) * (filled.ndim - 1))
            blend = (1 - w) * values[a].astype(np.float64) + w * values[b].astype(np.float64)
            filled[a + 1:b] = np.round(blend) if filled.dtype.kind in "iu" else blend
            interpolated[a + 1:b] = True
    return filled, interpolated


def footage_observe(cfg: ObserveConfig, slow_motion: float) -> ObserveConfig:
    """`cfg` for footage that plays `slow_motion` times slower than real time, whose
    `target_fps` is meant on the real clock: the footage is sampled that many times more
    sparsely (within the accepted range of rates)."""
    if slow_motion == 1.0:
        return cfg
    rate = min(max(cfg.target_fps / slow_motion, videolib.MIN_TARGET_FPS),
               videolib.MAX_TARGET_FPS)
    return dataclasses.replace(cfg, target_fps=rate)


def observe(video: str | Path, cfg: ObserveConfig = ObserveConfig(), *,
            progress: bool = True) -> Observations:
    """Run MediaPipe Pose on a video and return its Observations (cached by input + settings).

    Raises PhysposeError for unreadable videos, bad time ranges or rates, and when the person is
    found in fewer than `cfg.min_detection_fraction` of the frames.
    """
    video = Path(video)
    info = videolib.probe(video)
    plan = videolib.plan_frames(info, cfg.target_fps, cfg.start, cfg.end)
    if plan.note:
        _log.warning("%s: %s", video, plan.note)
    cache = Cache("observe")
    key = stage_key("observe", version=OBSERVE_VERSION, files=[video],
                    config=dataclasses.replace(cfg, use_cache=True))
    if cfg.use_cache and (hit := cache.get(key)) is not None:
        for note in hit.pop(NOTES_KEY, ()):  # what the run that filled the cache warned about
            _log.warning("%s", str(note).replace(_Notes.VIDEO, str(video)))
        return _from_arrays(hit, source=str(video))
    notes = _Notes(video)
    _log.addFilter(notes)
    try:
        obs = _observe_uncached(video, info, plan, cfg, progress)
    finally:
        _log.removeFilter(notes)
    if cfg.use_cache:
        cache.put(key, {**_to_arrays(obs), NOTES_KEY: np.array(notes.messages, dtype=str)})
    return obs


NOTES_KEY = "observe_notes"  # the warnings of the run, kept with its cached result


class _Notes(logging.Filter):
    """Collects the warnings observe logs, so that a result served from the cache can give
    them again (a variable frame rate, a person followed in a crop or found backwards...).
    A filter, not a handler: it lets every record through, and a handler on the logger would
    keep Python's last-resort output from printing them where no logging is configured."""

    VIDEO = "<video>"  # stands for the video's path, which a cache hit may not share

    def __init__(self, video: Path) -> None:
        super().__init__()
        self.video = str(video)
        self.messages: list[str] = []

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno >= logging.WARNING:
            self.messages.append(record.getMessage().replace(self.video, self.VIDEO))
        return True


def _observe_uncached(video: Path, info: videolib.VideoInfo, plan: videolib.FramePlan,
                      cfg: ObserveConfig, progress: bool) -> Observations:
    """observe() past its cache: detect, look again where needed, leave out torn detections,
    map a turning camera's detections into the middle frame's view."""
    cuts = CutFinder()
    obs = _detect_all(info, plan, cfg, progress, check=False, cuts=cuts)
    zoomed, seed, masked_to = False, None, None
    if cfg.person is None and obs.detected.sum() < cfg.min_detection_fraction * obs.num_frames:
        # Perhaps the person is too small for the detector's view of the whole frame: look
        # for them in tiles of a few frames, then follow them in a crop.
        seed = _find_small_person(info, plan, cfg)
    elif cfg.person is None and _small_and_patchy(obs, info.image_size):
        # Found, but small and lost now and then: follow the same person in a crop.
        seed = Follower(obs.keypoints2d[np.argmax(obs.detected)], plan.fps, info.image_size)
    if seed is not None:
        _log.warning("%s: the person is small in the image; following them in a crop", video)
        again = _detect_all(info, plan, cfg, progress, zoom=seed, check=False)
        if again.detected.sum() > obs.detected.sum():
            obs, zoomed = again, True
    _check_detection_rate(info.path, int(obs.detected.sum()), obs.num_frames, cfg)
    jumps = person_jumps(obs.keypoints2d, obs.detected, obs.fps)
    if jumps and cfg.person is None and not zoomed:
        # The tracker lost its person and took another: look again, with every frame masked
        # to where the subject (the longest track and those continuing it) can be.
        _log.warning("%s: the detected person jumps at %s s into the video; looking again "
                     "for one person only", video,
                     ", ".join(f"{obs.timestamps[f]:.2f}" for f in jumps))
        regions = subject_regions(obs.keypoints2d, obs.detected, obs.fps, info.image_size)
        again = _detect_all(info, plan, cfg, progress, regions=regions, check=False)
        left = person_jumps(again.keypoints2d, again.detected, again.fps)
        if len(left) < len(jumps) and again.detected.sum() >= cfg.min_detection_fraction \
                * again.num_frames:
            obs, masked_to = again, regions
    obs = _drop_unsure(obs, cfg)
    if cfg.follow_back and not zoomed and cfg.person is None:
        obs = _recover_head(info, plan, cfg, obs, video, masked_to)
    if obs.unsure is not None:
        _check_detection_rate(info.path, int(obs.detected.sum()), obs.num_frames, cfg)
    obs = unbridge_cuts(obs, cuts)
    if cfg.stabilize:
        motion = estimate_camera_motion(info, plan, obs)
        obs = stabilize(obs, motion)
        if motion.kind == "turning":
            _log.warning("%s: the camera turns (up to %.1f degrees from the middle frame's "
                         "view); the detections are mapped into that view", video,
                         motion.turned_deg)
    return obs


def _detect_all(info: videolib.VideoInfo, plan: videolib.FramePlan, cfg: ObserveConfig,
                progress: bool, regions: np.ndarray | None = None, check: bool = True,
                zoom: Follower | None = None, cuts: CutFinder | None = None) -> Observations:
    """Detect in every planned frame; regions (T, 4): image boxes outside which each frame is
    blacked out first (subject.py); zoom: follow the person in a crop around their last
    detection, starting from this follower. check: fail when too few frames have a
    detection. cuts: given on the first look, it is shown every frame, and the look warns
    where the video cuts (scene_cuts.py) and where its frames are not evenly spaced in time."""
    t = len(plan.indices)
    kp = np.zeros((t, NUM_LANDMARKS, 3))
    world = np.zeros((t, NUM_LANDMARKS, 3))
    mh, mw = mask_shape(info.image_size, cfg.mask_long_side)
    masks = np.zeros((t, mh, mw), np.uint8) if cfg.mask_long_side > 0 else None
    detected = np.zeros(t, bool)
    follower = zoom
    if follower is None and regions is None and cfg.person is not None:
        follower, zoomed = _follower(info, plan, cfg)
        zoom = follower if zoomed else None
    read = 0
    bar = tqdm(total=t, unit="frame", desc=f"observe {info.path.name}", disable=not progress,
               leave=False)
    with bar, PoseDetector(cfg) as detector:
        times: list[float] = []
        for i, (_, image) in enumerate(videolib.read_frames(info, plan.indices, times)):
            read = i + 1
            bar.update()
            if cuts is not None:
                cuts.see(image)
            if zoom is not None:
                found = detect_in_crop(detector, image, zoom.region(),
                                       (mh, mw) if masks is not None else None)
            elif regions is not None:
                found = detector.detect(mask_outside(image, regions[i]))
            elif follower is not None:
                found = detector.detect(mask_outside(image, follower.region()))
            else:
                found = detector.detect(image)
            if follower is not None:
                follower.update(None if found is None else found.keypoints2d)
            if found is None:
                continue
            detected[i] = True
            kp[i], world[i] = found.keypoints2d, found.world_landmarks
            if masks is not None and found.mask is not None:
                masks[i] = found.mask
    if cuts is not None and (message := videolib.drift_message(
            info, videolib.timing_drift(info, plan.indices, times))):
        _log.warning("%s", message)
    if cuts is not None and (message := cut_message([float(plan.timestamps[i])
                                                      for i in cuts.frames])):
        _log.warning("%s: %s", info.path, message)
    if read < t:  # the file ended a little early (within the container's counting slack)
        kp, world, detected = kp[:read], world[:read], detected[:read]
        masks = None if masks is None else masks[:read]
    if check or read == 0:
        _check_detection_rate(info.path, int(detected.sum()), read, cfg)
    kp, world, masks, interpolated = _fill_all_gaps(kp, world, masks, detected,
                                                    cfg.max_gap_frames)
    return Observations(
        source=str(info.path), fps=plan.fps, image_size=info.image_size,
        timestamps=plan.timestamps[:read].astype(np.float64), keypoints2d=kp, detected=detected,
        interpolated=interpolated, world_landmarks=world, masks=masks,
        frame_indices=plan.indices[:read].astype(np.int64))


def unbridge_cuts(obs: Observations, cuts: CutFinder) -> Observations:
    """The observations with every gap that was filled between two shots (its detections
    on either side of a cut, in pictures unlike each other) left unfilled: the two may be two
    people or two places, and no motion joins them. A blackout or a flash within one shot
    stays filled."""
    interpolated = np.asarray(obs.interpolated, dtype=bool)
    hits = np.flatnonzero(obs.detected)
    clear = np.zeros_like(interpolated)
    for a, b in zip(hits[:-1], hits[1:]):
        if b - a > 1 and interpolated[a + 1:b].any() and cuts.between(int(a), int(b)):
            clear[a + 1:b] = True
    if not clear.any():
        return obs
    return obs.replace(keypoints2d=_zeroed(obs.keypoints2d, clear),
                       interpolated=interpolated & ~clear,
                       world_landmarks=_zeroed(obs.world_landmarks, clear),
                       masks=_zeroed(obs.masks, clear))


def _zeroed(values: np.ndarray | None, frames: np.ndarray) -> np.ndarray | None:
    """A copy of per-frame `values` (T, ...) with the (T,) bool `frames` set to 0 (no
    detection there); None stays None."""
    return None if values is None else np.where(
        frames.reshape((-1,) + (1,) * (values.ndim - 1)), 0, values).astype(values.dtype)


def _drop_unsure(obs: Observations, cfg: ObserveConfig) -> Observations:
    """The observations without the detections whose person mask was unsure (torn landmarks,
    mask_quality.py); the gaps they leave are filled as any other (fill_gaps)."""
    if obs.masks is None or cfg.unsure_mask_band <= 0:
        return obs
    unsure = unsure_frames(obs.masks, obs.detected, _band_bound(obs.masks, cfg))
    if not unsure.any():
        return obs
    detected = obs.detected & ~unsure
    kp, world, masks, interpolated = _fill_all_gaps(
        _zeroed(obs.keypoints2d, ~detected), _zeroed(obs.world_landmarks, ~detected),
        _zeroed(obs.masks, ~detected), detected, cfg.max_gap_frames)
    return obs.replace(keypoints2d=kp, detected=detected, interpolated=interpolated,
                       world_landmarks=world, masks=masks, unsure=unsure)


def _recover_head(info: videolib.VideoInfo, plan: videolib.FramePlan, cfg: ObserveConfig,
                  obs: Observations, video: Path, regions: np.ndarray | None = None
                  ) -> Observations:
    """The clip's head before the first sure detection (where MediaPipe's detector missed the
    person, or its detections were left out as torn), detected again by a pass that runs
    backwards from just after it: the tracker, started on the person, often keeps them where
    the detector alone could not find them (Sports2D's demo: frames 0-7, against a sun flare).
    Backward detections are kept from the first sure frame down while each is found, is the
    person of the frame after it, has about as many landmarks inside the image as the first
    sure one (HEAD_VIEW_LOSS: a person walking into view is not followed back out of it) and
    has a sure mask (mask_quality.band_limit), and only if the backward pass found the forward
    pass's person at the first sure frame. regions: the image boxes the forward pass was
    masked to."""
    first = int(np.argmax(obs.detected)) if obs.detected.any() else 0
    if first == 0 or first > MAX_HEAD_SECONDS * obs.fps:
        return obs
    found = _detect_backwards(info, plan, cfg, min(first + HEAD_WARMUP, obs.num_frames - 1),
                              regions)
    if len(found) <= first or found[first] is None:
        return obs
    if not _same_person(obs.keypoints2d[first], found[first].keypoints2d):
        return obs   # the backward pass followed someone else
    limit = np.inf if obs.masks is None else band_limit(
        band_width(obs.masks[obs.detected]), _band_bound(obs.masks, cfg))
    # MediaPipe's visibilities do not tell a person beyond the edge (0.9 for one mostly out).
    in_view = inside_image(obs.keypoints2d[first], obs.image_size).mean() - HEAD_VIEW_LOSS
    kept = []
    for i in range(first - 1, -1, -1):
        f = found[i]
        if f is None or not _same_person(found[i + 1].keypoints2d, f.keypoints2d) \
                or inside_image(f.keypoints2d, obs.image_size).mean() < in_view or (
                    obs.masks is not None and f.mask is not None
                    and not band_width(f.mask[None])[0] <= limit):
            break   # lost, jumped to someone else, leaving the picture, or torn
        kept.append(i)
    if not kept:
        return obs
    kp, world = obs.keypoints2d.copy(), None if obs.world_landmarks is None \
        else obs.world_landmarks.copy()
    masks = None if obs.masks is None else obs.masks.copy()
    detected, unsure = obs.detected.copy(), None if obs.unsure is None else obs.unsure.copy()
    for i in kept:
        f = found[i]
        kp[i] = f.keypoints2d
        if world is not None:
            world[i] = f.world_landmarks
        if masks is not None:
            masks[i] = 0 if f.mask is None else cv2.resize(
                f.mask, masks.shape[:0:-1], interpolation=cv2.INTER_AREA)
        detected[i] = True
        if unsure is not None:
            unsure[i] = False
    _log.warning("%s: the person was found at %.2f-%.2f s by following them backwards in time "
                 "from %.2f s (the detector had missed them there, or torn them)", video,
                 obs.timestamps[min(kept)], obs.timestamps[first - 1], obs.timestamps[first])
    return obs.replace(keypoints2d=kp, world_landmarks=world, masks=masks, detected=detected,
                       unsure=None if unsure is None or not unsure.any() else unsure)


def _band_bound(masks: np.ndarray, cfg: ObserveConfig) -> float:
    """cfg.unsure_mask_band (mask pixels at a 256-pixel mask) at these masks' size."""
    return cfg.unsure_mask_band * max(np.asarray(masks).shape[1:]) / 256


def _same_person(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two detections' (33, 3) landmarks are one person in consecutive looks: the
    boxes of their confident landmarks have centres within half of the first box's diagonal."""
    centres, diagonals, ok = image_boxes(np.stack([a, b]))
    return bool(ok.all() and np.linalg.norm(centres[0] - centres[1]) <= 0.5 * diagonals[0])


def _detect_backwards(info: videolib.VideoInfo, plan: videolib.FramePlan, cfg: ObserveConfig,
                      last: int, regions: np.ndarray | None = None
                      ) -> list[FrameDetection | None]:
    """MediaPipe on the planned frames last, last - 1, ..., 0 (one tracking pass), each
    masked to its region where given; the detections in frame order, landmarks in the whole
    frame's pixels. The frames are held in memory, shrunk to MAX_HEAD_LONG_SIDE."""
    width, height = info.image_size
    scale = min(1.0, MAX_HEAD_LONG_SIDE / max(width, height))
    frames = []
    for i, (_, image) in enumerate(videolib.read_frames(info, plan.indices[:last + 1])):
        if regions is not None:
            image = mask_outside(image, regions[i])
        frames.append(image if scale == 1.0 else cv2.resize(
            image, (round(width * scale), round(height * scale)), interpolation=cv2.INTER_AREA))
    found: list[FrameDetection | None] = [None] * len(frames)
    with PoseDetector(cfg) as detector:
        for i in range(len(frames) - 1, -1, -1):
            found[i] = detector.detect(frames.pop())
    if scale < 1.0:
        for i, f in enumerate(found):
            if f is not None:
                kp = f.keypoints2d.copy()
                kp[:, :2] /= scale
                found[i] = dataclasses.replace(f, keypoints2d=kp)
    return found


def _follower(info: videolib.VideoInfo, plan: videolib.FramePlan, cfg: ObserveConfig
              ) -> tuple[Follower, bool]:
    """Find the person at `cfg.person` in the first planned frame (the whole image first, then
    smaller and smaller boxes around the point; then those boxes cropped and scaled up, for a
    person too small to be found otherwise) and follow them from there. Returns the follower
    and whether to follow in a crop (zoomed)."""
    x, y = cfg.person
    width, height = info.image_size
    first = f"the first analysed frame ({plan.timestamps[0]:.2f} s)"
    if not (0 <= x < width and 0 <= y < height):
        raise PhysposeError(f"--person {x:g},{y:g} is outside the {width}x{height} image",
                            path=info.path, remedy="give a pixel on the person in "
                            f"{first}, origin at the top left")
    frames = videolib.read_frames(info, plan.indices[:1])
    try:
        _, image = next(frames)
    finally:
        frames.close()
    regions = seed_regions((x, y), info.image_size)
    with PoseDetector(cfg, static=True) as detector:
        for region in regions:
            found = detector.detect(mask_outside(image, region))
            if found is not None and covers(found.keypoints2d, (x, y)):
                return Follower(found.keypoints2d, plan.fps, info.image_size), False
        for region in regions[1:]:
            found = detect_in_crop(detector, image, region)
            if found is not None and covers(found.keypoints2d, (x, y)):
                return Follower(found.keypoints2d, plan.fps, info.image_size), True
    raise PhysposeError(f"no person found at --person {x:g},{y:g} in {first}",
                        path=info.path, frame=int(plan.indices[0]),
                        remedy="give a pixel on the person's body there (origin at the top "
                               "left), or a --start at which the whole person is in view")


SEARCH_FRAMES = 4   # frames searched, spread over the clip, for a person the first look missed
SMALL_PERSON = 0.4  # a person whose detections' median box height is under this fraction of
PATCHY = 0.9        # the image height, found in fewer than this fraction of the frames, is
                    # looked for again in a crop


def _small_and_patchy(obs: Observations, image_size: tuple[int, int]) -> bool:
    """Whether the first look found a small person (SMALL_PERSON) in only some frames (PATCHY)."""
    lo, hi, ok = image_box_corners(obs.keypoints2d[obs.detected])
    if obs.detected.mean() >= PATCHY or not ok.any():
        return False
    return float(np.median(hi[ok, 1] - lo[ok, 1])) < SMALL_PERSON * image_size[1]


def _find_small_person(info: videolib.VideoInfo, plan: videolib.FramePlan, cfg: ObserveConfig
                       ) -> Follower | None:
    """Look for a person in square tiles (subject.tiles) of up to SEARCH_FRAMES frames spread
    over the clip; the first frame with one gives the follower: the tallest detection among
    those with a mean landmark visibility of at least MIN_SEED_VISIBILITY, detected again in a
    crop around itself so that the whole body is seen."""
    picks = np.unique(np.linspace(0, len(plan.indices) - 1, SEARCH_FRAMES).round().astype(int))
    with PoseDetector(cfg, static=True) as detector:
        for _, image in videolib.read_frames(info, plan.indices[picks]):
            hits = []
            for tile in tiles(info.image_size):
                found = detect_in_crop(detector, image, tile)
                box = None if found is None else detection_box(found.keypoints2d)
                if box is not None and found.keypoints2d[:, 2].mean() >= MIN_SEED_VISIBILITY:
                    hits.append((float(box[3] - box[1]), box))
            for _, box in sorted(hits, key=lambda h: -h[0]):
                grow = 0.5 * np.linalg.norm(box[2:] - box[:2])
                found = detect_in_crop(detector, image, np.concatenate([box[:2] - grow,
                                                                        box[2:] + grow]))
                if found is not None and detection_box(found.keypoints2d) is not None:
                    return Follower(found.keypoints2d, plan.fps, info.image_size)
    return None


def _check_detection_rate(path: Path, found: int, total: int, cfg: ObserveConfig) -> None:
    if total == 0:
        raise PhysposeError("no frames could be decoded", path=path,
                            remedy="check the file plays in a video player; re-encode it")
    if found == 0 or found < cfg.min_detection_fraction * total:
        raise PhysposeError(
            f"a person was found in only {found} of {total} frames "
            f"({100 * found / total:.0f}%, need {100 * cfg.min_detection_fraction:.0f}%)",
            path=path,
            remedy="use a video where one person is fully visible and reasonably large, or "
                   "pick a time range with --start/--end where they are (from Python, "
                   "ObserveConfig.min_detection_confidence lowers the detector's threshold)")


def _to_arrays(obs: Observations) -> dict[str, np.ndarray]:
    arrays = {f.name: getattr(obs, f.name) for f in dataclasses.fields(obs)}
    return {k: np.asarray(v) for k, v in arrays.items() if v is not None and k != "source"}


def _from_arrays(arrays: dict[str, np.ndarray], source: str) -> Observations:
    d = dict(arrays)
    if "camera_motion" in d:
        d["camera_motion"] = str(d["camera_motion"])
    return Observations(source=source, fps=float(d.pop("fps")),
                        image_size=tuple(int(v) for v in d.pop("image_size")), **d)
