"""Problems in the input that a user should hear about before trusting a reconstruction.

physpose follows one person standing on one modelled floor. Two common ways real footage
breaks that, found on a real clip the project had not seen (Sports2D's demo: the detector
follows a man standing on a 2 m high box, jumps to a woman walking on the lawn while he
somersaults off it, and back), and what the dynamics stage makes of them:

- `person_jumps`: the detected person moves further between two detections than a body can
  (another person, or a cut in the video). The fit then joins two people into one motion.
- `raised_runs`: the kinematic estimate's feet stay well above the floor for longer than any
  jump lasts: the person stands on something the scene lacks, or the floor was misjudged.
  Without a support the simulated body falls to the floor and every sample of those windows is
  invalid; `physpose.supports` gives the scene a box under the feet there.
- `unsure_message`: detections the observe stage left out because MediaPipe's person mask
  was a blurred blob there (physpose.mask_quality): their landmarks were torn.
- `hidden_feet_share`: how often no foot landmark is seen (the feet are out of the picture or
  hidden). The detector then guesses where the feet are, and the floor the kinematic fit puts
  under them is a guess too.
- `invalid_window_runs`: the frames of dynamics windows in which no simulated sample stayed
  valid (the output there is the least bad fall, not a reconstruction).
- `unrecorded_force_runs`: frames whose simulated forces are missing because their windows
  were resumed from checkpoints an earlier physpose wrote without them.
- `rate_message`: an analysis rate above the rates the kinematic fit was measured at.
- `label_exchange_message`: where the kinematic fit's swap repair kept a limb's left/right
  labels exchanged against the detector's for half a second or more (a wrong repair's sign).
- `camera_pose_message`: where the kinematic fit put the camera relative to the floor it
  found (`metrics.camera_height`, `metrics.camera_tilt`). Under LOW_CAMERA above it, below
  it, or tilted TILTED_CAMERA or more from upright, the person was most likely low to the
  floor for the whole clip (lying, crawling, kneeling): the plane fit cannot tell the floor
  from the body's other sides then, and the floor, the placement and the physics are wrong
  (docs/kinematics.md, limits).
- `stride_period`: how long the feet take to alternate when the person walks or runs. A
  stride far slower than people walk or run hints at slow-motion footage, which the physics
  must be told of (`--slow-motion`): under real gravity it cannot move as slowly as the person
  seems to.
"""

from __future__ import annotations

import numpy as np

from physpose.joints import LANDMARK_INDEX
from physpose.metrics import foot_points
from physpose.reconstruction import frame_runs
from physpose.scene import parse_obstacle

MIN_CONFIDENCE = 0.3       # landmarks that count for the person's image box
LOW_CAMERA = 0.3           # m: a camera found lower above the floor is warned about
# degrees from upright (pitch and roll together): a camera found tilted more is warned about.
# Stop 75: upright people gave at most 35.6 (pose2sim's cam04, truly so tilted; 187 cached
# fits of the benchmark's clips and views); motion-capture clips laid flat gave 29-127 in 15
# runs, 10 of them over 45 (scratch lyingroll75.py).
TILTED_CAMERA = 45.0
JUMP_SIZES = 0.4           # a jump: the box centre moves more than this many box diagonals ...
JUMP_SPEED = 6.0           # ... plus this many box diagonals per second between the detections
RAISED_HEIGHT = 0.3        # m, lowest sole point above the floor ...
RAISED_SECONDS = 1.0       # ... for at least this long (no jump keeps both feet up that long)
HIDDEN_FEET_SHARE = 0.3    # warn when no foot landmark is seen in this share of the frames
# A stride (left foot forward to left foot forward again) takes about 1.0-1.2 s walking and
# 0.6-0.8 s running; one this slow on the real clock hints at undeclared slow motion.
SLOW_STRIDE_S = 2.0
STRIDE_S = (0.7, 1.2)       # s, the stride a hint's suggested slow-motion factor assumes
STRIDE_REGULARITY = 0.8     # autocorrelation a periodic stride reaches at one period
STRIDE_AMPLITUDE = 0.15     # torso lengths, the least spread of the feet's alternation
STRIDE_CYCLES = 1.5         # strides that must be seen
LONGEST_STRIDE_S = 10.0     # s, the slowest alternation looked for
TUNED_RATE_HZ = 50.0        # the fastest analysis rate measured to work (tuned at 25 Hz)
_STRIDE_LANDMARKS = [LANDMARK_INDEX[n] for n in ("left_ankle", "right_ankle", "left_shoulder",
                                                 "right_shoulder", "left_hip", "right_hip")]
FOOT_LANDMARKS = [LANDMARK_INDEX[f"{side}_{part}"] for side in ("left", "right")
                  for part in ("ankle", "heel", "foot_index")]


def image_box_corners(keypoints2d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per frame: the low and high corners (T, 2) of the confident landmarks' image box (0
    where too few), and whether the frame has at least 4 such landmarks (T,)."""
    keypoints2d = np.asarray(keypoints2d, dtype=float)
    conf = keypoints2d[..., 2] >= MIN_CONFIDENCE
    xy = keypoints2d[..., :2]
    lo = np.where(conf[..., None], xy, np.inf).min(axis=1)
    hi = np.where(conf[..., None], xy, -np.inf).max(axis=1)
    ok = conf.sum(axis=1) >= 4
    lo[~ok], hi[~ok] = 0.0, 0.0
    return lo, hi, ok


def image_boxes(keypoints2d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per frame: the centre (T, 2) and diagonal (T,) of the confident landmarks' image box,
    and whether the frame has at least 4 such landmarks (T,)."""
    lo, hi, ok = image_box_corners(keypoints2d)
    return 0.5 * (lo + hi), np.linalg.norm(hi - lo, axis=-1), ok


def size_ratio(a: float, b: float) -> float:
    """How many times larger the larger of two box diagonals is (>= 1)."""
    return max(a, b) / max(min(a, b), 1e-9)


def person_jumps(keypoints2d: np.ndarray, detected: np.ndarray, fps: float) -> list[int]:
    """Frames at which the detected person jumps from where it was at the previous detection
    further than a body moves: more than JUMP_SIZES + JUMP_SPEED x (seconds between them) box
    diagonals (the mean of the two boxes), or the box's size changes more than 2x.

    Interpolated frames are skipped (they bridge a gap; the jump shows between the two real
    detections around it)."""
    centre, diagonal, ok = image_boxes(keypoints2d)
    frames = np.flatnonzero(np.asarray(detected, dtype=bool) & ok)
    jumps = []
    for a, b in zip(frames[:-1], frames[1:]):
        size = 0.5 * (diagonal[a] + diagonal[b])
        moved = np.linalg.norm(centre[b] - centre[a])
        if moved > size * (JUMP_SIZES + JUMP_SPEED * (b - a) / fps) \
                or size_ratio(diagonal[a], diagonal[b]) > 2.0:
            jumps.append(int(b))
    return jumps


def inside_image(keypoints2d: np.ndarray, image_size: tuple[int, int]) -> np.ndarray:
    """(...,) bool: which landmarks (..., 3) lie inside an image of (width, height) pixels."""
    x, y = keypoints2d[..., 0], keypoints2d[..., 1]
    return (x >= 0) & (x < image_size[0]) & (y >= 0) & (y < image_size[1])


def hidden_feet_share(keypoints2d: np.ndarray, valid: np.ndarray,
                      image_size: tuple[int, int]) -> float:
    """Share of the frames with landmarks (`valid`) in which no ankle, heel or toe landmark is
    seen: each below MIN_CONFIDENCE or outside the image. 0 when no frame is valid."""
    keypoints2d = np.asarray(keypoints2d, dtype=float)
    valid = np.asarray(valid, dtype=bool)
    if not valid.any():
        return 0.0
    feet = keypoints2d[valid][:, FOOT_LANDMARKS]
    seen = (inside_image(feet, image_size) & (feet[..., 2] >= MIN_CONFIDENCE)).any(axis=1)
    return float(1.0 - seen.mean())


def stride_period(keypoints2d: np.ndarray, valid: np.ndarray, fps: float) -> float | None:
    """Seconds (at `fps`) the feet take to alternate where the person steps periodically, else
    None. The signal is the image distance between the ankles along its main direction, in
    torso lengths; the period is the lag of its autocorrelation's first peak (on the first
    positive lobe after a negative one), which must reach STRIDE_REGULARITY within
    1 / STRIDE_CYCLES of the frames seen."""
    kp = np.asarray(keypoints2d, dtype=float)
    seen = np.asarray(valid, bool) & (kp[:, _STRIDE_LANDMARKS, 2] >= MIN_CONFIDENCE).all(axis=1)
    if seen.mean() < 0.8 or seen.sum() < 10:
        return None
    frames = np.arange(len(kp))
    spread = kp[:, _STRIDE_LANDMARKS[0], :2] - kp[:, _STRIDE_LANDMARKS[1], :2]
    spread = np.stack([np.interp(frames, frames[seen], spread[seen, i]) for i in range(2)], 1)
    shoulders, hips = (kp[seen][:, _STRIDE_LANDMARKS[i:i + 2], :2].mean(axis=1) for i in (2, 4))
    torso = np.linalg.norm(shoulders - hips, axis=1)
    spread -= spread.mean(axis=0)
    direction = np.linalg.svd(spread, full_matrices=False)[2][0]
    x = spread @ direction / max(float(np.median(torso)), 1e-9)
    if x.std() < STRIDE_AMPLITUDE:
        return None
    n = len(x)
    lags = np.arange(1, int(min(n / STRIDE_CYCLES, LONGEST_STRIDE_S * fps)) + 1)
    corr = np.array([np.corrcoef(x[:-k], x[k:])[0, 1] for k in lags])
    # The first positive lobe after the first negative one: one period (not a multiple).
    below = np.flatnonzero(corr < 0)
    above = below[0] + np.flatnonzero(corr[below[0]:] >= 0) if len(below) else []
    if not len(above):
        return None
    lobe = corr[above[0]:]
    end = np.flatnonzero(lobe < 0)
    best = above[0] + int(np.argmax(lobe[:end[0]] if len(end) else lobe))
    return float(lags[best] / fps) if corr[best] >= STRIDE_REGULARITY else None


def raised_runs(joints: np.ndarray, fps: float) -> list[tuple[int, int, float]]:
    """(first, last, median height m) of each stretch of at least RAISED_SECONDS in which
    both feet of a motion (T, 21, 3), world z up with the floor at 0, stay more than
    RAISED_HEIGHT above the floor."""
    lowest = foot_points(np.asarray(joints, dtype=float))[..., 2].min(axis=(1, 2))
    out = []
    for a, b in frame_runs(lowest > RAISED_HEIGHT):
        if (b - a + 1) / fps >= RAISED_SECONDS:
            out.append((a, b, float(np.median(lowest[a:b + 1]))))
    return out


def invalid_window_runs(windows: list[dict], sequential: bool = True
                        ) -> list[tuple[int, int]]:
    """(first, last) frames that dynamics windows with no valid sample gave the output, merged.

    windows: the run's window records, in order (``frames``: the planned [first, last]).
    Sequential windows each give the output only their frames up to the next window's start
    (a window cut where it strayed is followed by one starting at the cut), so a window's
    look-ahead past that is not counted; independent windows are cross-faded over their whole
    spans, so each counts whole.
    """
    records = [w for w in windows if isinstance(w, dict) and "frames" in w]
    spans = []
    for k, w in enumerate(records):
        if w.get("valid") is not False:
            continue
        first, last = w["frames"]
        if sequential and k + 1 < len(records):
            last = min(last, records[k + 1]["frames"][0] - 1)
        spans.append((first, last))
    spans.sort()
    merged: list[list[int]] = []
    for a, b in spans:
        if merged and a <= merged[-1][1] + 1:
            merged[-1][1] = max(merged[-1][1], b)
        else:
            merged.append([a, b])
    return [(int(a), int(b)) for a, b in merged]


def unrecorded_force_runs(grf: np.ndarray | None) -> list[tuple[int, int]]:
    """(first, last) frames whose ground reaction forces (T, 3, 3) are not finite."""
    if grf is None:
        return []
    return frame_runs(~np.isfinite(grf).all(axis=(1, 2)))


def _at(frame: int, fps: float) -> str:
    return f"{frame} ({frame / fps:.2f} s)"


def _span(a: int, b: int, fps: float) -> str:
    return f"{a}-{b} ({a / fps:.2f}-{(b + 1) / fps:.2f} s)"


def jumps_message(frames: list[int], fps: float, times: list[float] | None = None
                  ) -> str | None:
    """A warning on `person_jumps`, or None; `times`, where given, are the frames' seconds
    into the video (what --start/--end take), else they are counted from the first frame."""
    if not frames:
        return None
    if times is not None and len(times) == len(frames):
        where = ", ".join(f"{f} ({t:.2f} s into the video)" for f, t in zip(frames, times))
    else:
        where = ", ".join(_at(f, fps) for f in frames)
    return (f"input: the detected person jumps further than a body moves at frame"
            f"{'s' * (len(frames) > 1)} {where}: the detector has probably switched to "
            "another person (or the video cuts there). physpose follows one person, so the "
            "motion joins them; analyse one person's stretch with --start/--end, or crop the "
            "video to that person")


def unsure_message(times: list[float]) -> str | None:
    """A warning on the detections observe left out as torn (`Observations.unsure`), given
    their times in seconds into the footage, or None."""
    if not times:
        return None
    at = ", ".join(f"{t:.2f}" for t in times[:8]) + (f" and {len(times) - 8} more"
                                                     if len(times) > 8 else "")
    return (f"input: MediaPipe was unsure where the person is in {len(times)} frame"
            f"{'s' * (len(times) > 1)} (at {at} s into the video: a blurred person mask, "
            "e.g. glare or a first detection off the person); those detections were left out "
            "and the frames treated as gaps (docs/kinematics.md, Torn detections)")


def hidden_feet_message(share: float) -> str | None:
    """A warning on `hidden_feet_share`, or None below HIDDEN_FEET_SHARE."""
    if share < HIDDEN_FEET_SHARE:
        return None
    return (f"input: the feet are out of the picture or hidden in {100 * share:.0f}% of the "
            "frames with a person: the detector guesses where they are, so the floor, the "
            "foot contacts and the physics resting on them are guesses too. Film the whole "
            "person, feet included")


def slow_stride_message(period: float | None, slow_motion: float = 1.0) -> str | None:
    """A hint that the footage may be slow motion, where `period` (s, on the clock the
    reconstruction took as real, after `slow_motion`) is slower than SLOW_STRIDE_S; else None."""
    if period is None or period <= SLOW_STRIDE_S:
        return None
    low, high = (slow_motion * period / stride for stride in sorted(STRIDE_S, reverse=True))
    told = "" if slow_motion == 1.0 else f" even at the declared {slow_motion:g}x slow motion"
    return (f"input: the feet alternate every {period:.1f} s{told}, slower than people walk "
            f"(a stride of about 1.0-1.2 s) or run (0.6-0.8 s). If the footage is slow motion "
            f"(filmed at a high frame rate, played slower), say so, e.g. --slow-motion "
            f"{low:.1f} to {high:.1f} for this stride: under real gravity the simulated body "
            "cannot move as slowly as the person seems to (docs/dynamics.md, Slow-motion "
            "footage)")


def rate_message(fps: float) -> str | None:
    """A warning where the analysis rate (real clock) is above TUNED_RATE_HZ, else None."""
    if fps <= TUNED_RATE_HZ:
        return None
    return (f"input: analysed at {fps:g} frames per second of real time; physpose is tuned at "
            f"25 and measured to work up to {TUNED_RATE_HZ:g}. At 100 on motion capture the "
            "physics missed the detections by more and its feet slid more (docs/kinematics.md, "
            "Conventions and limits). Use --fps 25 unless the motion needs more")


def trimmed_message(trimmed: list[int] | None, total: int, fps: float,
                    times: list[float] | None = None) -> str | None:
    """A note on the frames left out before and after the person is seen (no detection, or
    only ones observe left out as torn), or None. trimmed: [first, last] frames kept of
    `total`; times: seconds into the footage of those two frames (results written before
    stop 74 have none: then seconds from the first analysed frame)."""
    if not trimmed:
        return None
    first, last = trimmed
    if times is None:
        parts = [f"before {first / fps:.2f} s" if first > 0 else "",
                 f"after {(last + 1) / fps:.2f} s" if last < total - 1 else ""]
        return (f"input: the person is not seen {' or '.join(p for p in parts if p)} (of "
                f"{total / fps:.2f} s analysed): only frames {first}-{last} are reconstructed "
                "(the output's frame_indices say which video frames those are)")
    parts = [f"before {times[0]:.2f} s" if first > 0 else "",
             f"after {times[1]:.2f} s" if last < total - 1 else ""]
    return (f"input: the person is not seen {' or '.join(p for p in parts if p)} into the "
            f"video: only frames {first}-{last} of the {total} analysed are reconstructed (the "
            "video_frame and video_time columns of joints.csv and forces.csv say where each "
            "frame is)")


def camera_message(kind: str | None) -> str | None:
    """A warning where the camera moved along while filming (camera_motion.py), or None."""
    if kind != "moving":
        return None
    return ("input: the camera moves (or zooms) while filming, not only turns: physpose "
            "assumes a static camera, so the motion is reconstructed as the camera saw it; a "
            "person the camera follows seems to walk or run on the spot, and the physics, which "
            "cannot, strays from them and restarts. Film from a fixed point without zooming "
            "(turning to follow is fine), or try --camera-travel travelling: the physics then "
            "follows the person's own path, the camera's read off the standing feet "
            "(docs/dynamics.md, A travelling camera)")


def raised_message(runs: list[tuple[int, int, float]], fps: float, supported: bool = True
                   ) -> str | None:
    """A warning on `raised_runs`, or None; `supported`: whether a support box was added."""
    if not runs:
        return None
    where = ", ".join(f"{_span(a, b, fps)}, {h:.2f} m up" for a, b, h in runs)
    what = ("physpose puts a box under the feet there (--no-auto-support: none, and the "
            "simulated body falls)" if supported else
            "no support was added (--no-auto-support), so the simulated body falls there")
    return (f"kinematics: both feet stay above the floor for longer than a jump lasts at frames "
            f"{where}: the person stands on something the scene does not have, or the floor "
            f"was misjudged. {what}; give the real support with --obstacle "
            "box:x,y,z,sx,sy,sz (centre and sizes in world metres, docs/body_model.md)")


def seated_message(runs: list[tuple[int, int, float]], seats: tuple, fps: float) -> str | None:
    """A warning on `supports.seated_runs`, or None; `seats`: the boxes added (may be empty)."""
    if not runs:
        return None
    where = ", ".join(f"{_span(a, b, fps)}, seat {h:.2f} m up" for a, b, h in runs)
    what = (f"physpose puts a seat there ({' '.join(b.spec() for b in seats)}; "
            "--no-auto-support: none, and the simulated body falls)" if seats else
            "no seat was added (--no-auto-support), so the simulated body falls there")
    return (f"kinematics: the person sits at frames {where} (thighs level, the trunk behind "
            f"the feet): no body balances so on its feet alone. {what}; give the real seat "
            "with --obstacle box:x,y,z,sx,sy,sz[,yaw_deg] (centre and sizes in world metres)")


def label_exchange_message(runs: dict[str, list[list[int]]] | None, fps: float
                           ) -> str | None:
    """A warning on the kinematic fit's long label exchanges (`KinematicFit.label_exchanges`:
    limb group -> [first, last] frames), or None."""
    if not runs:
        return None
    where = "; ".join(f"the {name}' at frames " + ", ".join(_span(a, b, fps) for a, b in spans)
                      for name, spans in runs.items())
    return (f"kinematics: the swap repair kept left and right exchanged against the detector's "
            f"labels for half a second or longer ({where}). Seen from the side MediaPipe's 3d "
            "tells the limbs apart poorly, so the repair may have chosen the mirror image "
            "there: check those frames in the overlay (in Python, KinematicConfig(fix_swaps=False) "
            "turns the repair off)")


def camera_pose_message(height: float | None, tilt: float | None = None) -> str | None:
    """A warning when the kinematic fit put the camera under LOW_CAMERA above its floor, or
    tilted it TILTED_CAMERA degrees or more from upright (`metrics.camera_tilt`)."""
    found = []
    if height is not None and np.isfinite(height) and height < LOW_CAMERA:
        found.append(f"puts the camera {height:.2f} m above it" if height >= 0 else
                     f"puts the camera {-height:.2f} m below it")
    if tilt is not None and np.isfinite(tilt) and tilt >= TILTED_CAMERA:
        found.append(f"tilts the camera {tilt:.0f} degrees from upright (a level camera: 0; "
                     "filmed people: under 40)")
    if not found:
        return None
    return (f"kinematics: the floor found {' and '.join(found)}. Unless the camera really "
            "stood so (or the video lies on its side: turn it upright first), the person was "
            "low to the floor for the whole clip (lying, crawling, kneeling), where physpose "
            "cannot tell the floor from the body's other sides: the floor, the body's "
            "placement and the physics are then wrong (docs/kinematics.md, Conventions and "
            "limits). Analyse a stretch in which the person also stands (widen --start/--end)")


def invalid_message(runs: list[tuple[int, int]], fps: float) -> str | None:
    """A warning on `invalid_window_runs`, or None."""
    if not runs:
        return None
    where = ", ".join(_span(a, b, fps) for a, b in runs)
    return (f"physics: no simulated motion stayed valid (within 1 m of the estimate, above the "
            f"floor) at frames {where}; the physics output there is the least bad fall, not "
            "a reconstruction. Use the kinematic motion there (joints_kinematic)")


def unrecorded_forces_message(runs: list[tuple[int, int]], fps: float) -> str | None:
    """A warning on `unrecorded_force_runs`, or None."""
    if not runs:
        return None
    where = ", ".join(_span(a, b, fps) for a, b in runs)
    return (f"physics: no simulated forces at frames {where}: their windows were resumed from "
            "checkpoints an earlier physpose wrote without forces (the motion is the same). "
            "To have them, run again without resuming (physpose reconstruct --no-resume; "
            "physpose demo --no-cache)")


def warning_lines(found: dict, fps: float, slow_motion: float = 1.0) -> list[str]:
    """The warnings of a reconstruction's meta ``diagnostics`` (as the pipeline stores them),
    for a result at `fps` from footage played `slow_motion` times slower than real time."""
    lines = [rate_message(fps),
             trimmed_message(found.get("trimmed"), found.get("observed_frames", 0), fps,
                             found.get("trimmed_times")),
             camera_message(found.get("camera_motion")),
             unsure_message(found.get("unsure_detections", [])),
             jumps_message(found.get("person_jumps", []), fps,
                           found.get("person_jump_times")),
             hidden_feet_message(found.get("hidden_feet", 0.0)),
             camera_pose_message(found.get("camera_height"), found.get("camera_tilt")),
             label_exchange_message(found.get("label_exchanges"), fps),
             raised_message([tuple(r) for r in found.get("raised", [])], fps,
                            supported=bool(found.get("supports"))),
             seated_message([tuple(r) for r in found.get("seated", [])],
                            tuple(parse_obstacle(b) for b in found.get("seats", [])), fps),
             invalid_message([tuple(r) for r in found.get("invalid_windows", [])], fps),
             unrecorded_forces_message([tuple(r) for r in found.get("unrecorded_forces", [])],
                                       fps),
             slow_stride_message(found.get("stride_period"), slow_motion)]
    return [line for line in lines if line]
