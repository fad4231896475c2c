"""MediaPipe's own error per view, measured against the multi-view reference.

For each view the reference is re-triangulated from the *other* views (leave-one-out), so the
view's own detections do not pull the reference towards themselves; the in-sample 2d error is
reported beside it. Figures (all over detected frames, the 33 landmarks):

- 2d: pixel distance between the detections and the reference projected with the real camera;
  per-coordinate sigma split into a frame-to-frame ("white") part, std(diff)/sqrt(2), and the
  remaining slowly varying ("drift") part; outlier rate (error > 5 % of the image height); the
  person's height in the image, to rescale the figures to other framings.
- 3d: MediaPipe world landmarks (hip-centred, camera axes) against the reference rotated into the
  camera's axes and centred on its hips: mean error, Procrustes-aligned error, per-axis RMS and
  bias, the overall scale ratio, the depth (camera z) scale ratio, the factor on MediaPipe's
  depth that best predicts the reference's, and the two depths' uncentred correlation.
- left/right swaps: frames where exchanging a view's left and right legs (or arms) fits the
  reference much better than the labels given.

Run `python -m physpose.multiview.detector_error [FOLDER] --out docs/mediapipe_error.md`.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from physpose.joints import LANDMARK_INDEX, LANDMARK_NAMES, joints_from_landmarks
from physpose.metrics import mpjpe, mpjpe_pa, transform_points
from physpose.multiview.reference import (MultiviewReference, ReferenceConfig,
                                          build_multiview_reference, fill_missing,
                                          triangulate_observations)
from physpose.multiview.triangulate import TriangulationConfig
from physpose.observe import ObserveConfig
from physpose.paths import pose2sim_demo_dir
from physpose.pinhole import hip_ray_frames

OUTLIER_FRACTION = 0.05  # a 2d error above this fraction of the image height is an outlier
SWAP_GAIN = 0.5          # swapped labels fit this much better (error ratio) -> a swap
SWAP_MIN_PX = 20.0       # ... and the given labels are off by more than this, px
_HIPS = [LANDMARK_INDEX["left_hip"], LANDMARK_INDEX["right_hip"]]
_SWAP_PARTS = {"legs": ("knee", "ankle", "heel", "foot_index"),
               "arms": ("elbow", "wrist", "pinky", "index", "thumb")}


@dataclass(frozen=True)
class ViewError:
    """MediaPipe's error in one view (lengths in mm or px as named)."""

    view: str
    frames: int
    person_height_px: float       # median head-to-feet extent of the reference in the image
    image_height_px: int
    err2d_median_px: float        # leave-one-out reference
    err2d_mean_px: float
    err2d_in_sample_median_px: float
    sigma2d_px: float             # robust per-coordinate sigma (1.4826 MAD)
    sigma2d_white_px: float       # frame-to-frame part
    sigma2d_drift_px: float       # slowly varying part
    bias2d_px: tuple[float, float]
    outlier_rate: float           # fraction of landmark-frames with error > 5 % image height
    err3d_mean_mm: float          # 33 landmarks, hip-centred, camera axes
    err3d_median_mm: float
    err3d_joints_mm: float        # the project's 21 joints, pelvis-aligned (MPJPE)
    err3d_joints_pa_mm: float     # ... after per-frame Procrustes (MPJPE-PA)
    rms3d_axes_mm: tuple[float, float, float]   # camera x, y, z
    bias3d_axes_mm: tuple[float, float, float]
    scale_ratio: float            # size of MediaPipe's body / the reference's
    depth_scale_ratio: float      # MediaPipe hip-relative depth / reference's (LS fit)
    depth_predictor: float        # the factor on MediaPipe's depth best predicting the
                                  # reference's (LS fit the other way round)
    depth_correlation: float      # of the two hip-relative depths, uncentred (a cosine)
    swap_rate_legs: float         # fraction of frames with the legs' left/right exchanged
    swap_rate_arms: float
    ray_angle_deg: float          # mean angle between the optical axis and the ray to the hips
    err3d_ray_mean_mm: float      # as err3d_mean_mm, MediaPipe's landmarks turned from the
                                  # frame of that ray into camera axes
    err3d_ray_diff_se_mm: float   # standard error of the per-frame difference of the two


def _swap_index(parts: tuple[str, ...]) -> np.ndarray:
    idx = np.arange(len(LANDMARK_NAMES))
    for part in parts:
        left, right = LANDMARK_INDEX[f"left_{part}"], LANDMARK_INDEX[f"right_{part}"]
        idx[left], idx[right] = right, left
    return idx


def _swap_rate(kp: np.ndarray, ref2d: np.ndarray, parts: tuple[str, ...]) -> float:
    idx = _swap_index(parts)
    sel = [LANDMARK_INDEX[f"{s}_{p}"] for s in ("left", "right") for p in parts]
    given = np.linalg.norm(kp[:, sel] - ref2d[:, sel], axis=-1).mean(1)
    swapped = np.linalg.norm(kp[:, idx][:, sel] - ref2d[:, sel], axis=-1).mean(1)
    return float(np.mean((swapped < SWAP_GAIN * given) & (given > SWAP_MIN_PX)))


def view_error(ref: MultiviewReference, view: int) -> ViewError:
    """MediaPipe's error in view `view` against the reference from the other views."""
    cam, obs = ref.cameras[view], ref.views[view]
    loo = triangulate_observations(ref.cameras, ref.views, exclude=view)
    if not loo.valid.any(axis=0).all():
        raise ValueError(f"view {cam.name}: some landmarks are never seen by the other views")
    ref_loo = fill_missing(loo.points, loo.valid)
    ok = obs.detected & loo.valid.all(axis=1)
    kp = np.asarray(obs.keypoints2d)[ok, :, :2]
    ref2d = cam.project(ref_loo[ok])
    res = kp - ref2d
    err2d = np.linalg.norm(res, axis=-1)
    in_sample = np.linalg.norm(kp - cam.project(ref.landmarks[ok]), axis=-1)
    sigma = 1.4826 * np.median(np.abs(res - np.median(res, axis=(0, 1))))
    frames = np.flatnonzero(ok)
    step = np.diff(res, axis=0)[np.diff(frames) == 1]       # consecutive frames only
    white = 1.4826 * np.median(np.abs(step)) / np.sqrt(2)
    extent = ref2d[..., 1].max(1) - ref2d[..., 1].min(1)

    # 3d against the full reference: leaving a view out costs more accuracy in 3d (50-60 mm
    # on the demo) than the view's own pull on the triangulation.
    ref_cam = transform_points(cam.T_world2cam, ref.landmarks[ok])
    ref_cam -= ref_cam[:, _HIPS].mean(1, keepdims=True)
    mp = np.asarray(obs.world_landmarks)[ok]
    mp = mp - mp[:, _HIPS].mean(1, keepdims=True)
    d3 = (mp - ref_cam) * 1000
    conf = np.asarray(obs.keypoints2d)[ok, :, 2]
    cam_from_ray = hip_ray_frames(kp, conf, cam.K)
    d3_ray = (np.einsum("tij,tkj->tki", cam_from_ray, mp) - ref_cam) * 1000
    per_frame = np.linalg.norm(d3_ray, axis=-1).mean(1) - np.linalg.norm(d3, axis=-1).mean(1)
    mp_joints, ref_joints = joints_from_landmarks(mp), joints_from_landmarks(ref_cam)
    size = lambda x: np.sqrt((x ** 2).sum(-1).mean(-1))  # noqa: E731  per-frame RMS radius
    cross = (mp[..., 2] * ref_cam[..., 2]).sum()
    height = obs.image_size[1]
    return ViewError(
        view=cam.name, frames=int(ok.sum()), person_height_px=float(np.median(extent)),
        image_height_px=int(height),
        err2d_median_px=float(np.median(err2d)), err2d_mean_px=float(err2d.mean()),
        err2d_in_sample_median_px=float(np.median(in_sample)),
        sigma2d_px=float(sigma), sigma2d_white_px=float(white),
        sigma2d_drift_px=float(np.sqrt(max(sigma ** 2 - white ** 2, 0.0))),
        bias2d_px=tuple(float(v) for v in np.median(res, axis=(0, 1))),
        outlier_rate=float(np.mean(err2d > OUTLIER_FRACTION * height)),
        err3d_mean_mm=float(np.linalg.norm(d3, axis=-1).mean()),
        err3d_median_mm=float(np.median(np.linalg.norm(d3, axis=-1))),
        err3d_joints_mm=mpjpe(mp_joints, ref_joints),
        err3d_joints_pa_mm=mpjpe_pa(mp_joints, ref_joints),
        rms3d_axes_mm=tuple(float(v) for v in np.sqrt((d3 ** 2).mean(axis=(0, 1)))),
        bias3d_axes_mm=tuple(float(v) for v in d3.mean(axis=(0, 1))),
        scale_ratio=float(np.median(size(mp) / size(ref_cam))),
        depth_scale_ratio=float(cross / (ref_cam[..., 2] ** 2).sum()),
        depth_predictor=float(cross / (mp[..., 2] ** 2).sum()),
        depth_correlation=float(cross / np.sqrt((mp[..., 2] ** 2).sum()
                                                * (ref_cam[..., 2] ** 2).sum())),
        swap_rate_legs=_swap_rate(kp, ref2d, _SWAP_PARTS["legs"]),
        swap_rate_arms=_swap_rate(kp, ref2d, _SWAP_PARTS["arms"]),
        ray_angle_deg=float(np.degrees(np.arccos(np.clip(cam_from_ray[:, 2, 2], -1, 1))).mean()),
        err3d_ray_mean_mm=float(np.linalg.norm(d3_ray, axis=-1).mean()),
        err3d_ray_diff_se_mm=float(per_frame.std(ddof=1) / np.sqrt(len(per_frame))))


def detector_errors(ref: MultiviewReference) -> list[ViewError]:
    return [view_error(ref, i) for i in range(len(ref.cameras))]


def _pooled(errors: list[ViewError]) -> dict[str, float]:
    """Frame-weighted mean of every scalar figure over the views."""
    w = np.array([e.frames for e in errors], dtype=float)
    out = {}
    for key, value in asdict(errors[0]).items():
        if isinstance(value, float):
            out[key] = float(np.average([getattr(e, key) for e in errors], weights=w))
    return out


def render_markdown(ref: MultiviewReference, errors: list[ViewError], command: str) -> str:
    """docs/mediapipe_error.md: triangulation quality and MediaPipe's error per view."""
    tri = ref.reprojection_summary()
    plain = triangulate_observations(ref.cameras, ref.views,
                                     TriangulationConfig(inlier_px=np.inf))
    pooled = _pooled(errors)
    rows2d = [(e.view, e.frames, e.person_height_px, e.err2d_median_px, e.err2d_mean_px,
               e.err2d_in_sample_median_px, e.sigma2d_px, e.sigma2d_white_px, e.sigma2d_drift_px,
               f"{e.bias2d_px[0]:+.1f}, {e.bias2d_px[1]:+.1f}", 100 * e.outlier_rate,
               100 * e.swap_rate_legs, 100 * e.swap_rate_arms) for e in errors]
    rows3d = [(e.view, e.err3d_joints_mm, e.err3d_joints_pa_mm, e.err3d_mean_mm, e.err3d_median_mm,
               " / ".join(f"{v:.0f}" for v in e.rms3d_axes_mm),
               " / ".join(f"{v:+.0f}" for v in e.bias3d_axes_mm), e.scale_ratio,
               e.depth_scale_ratio, e.depth_predictor, e.depth_correlation) for e in errors]
    fmt = lambda row: "| " + " | ".join(  # noqa: E731
        f"{v:.2f}" if isinstance(v, float) and abs(v) < 2 else
        f"{v:.1f}" if isinstance(v, float) else str(v) for v in row) + " |"
    p = pooled
    image_h = errors[0].image_height_px
    lines = [
        "# MediaPipe Pose error on the multi-view reference", "",
        f"Produced by `{command}` (MediaPipe {ref.views[0].fps:g} fps input, "
        f"{ref.num_frames} frames x {len(ref.cameras)} views of `{Path(ref.folder).name}`, "
        "1080x1920 portrait videos). See `physpose/multiview/detector_error.py` for the "
        "definitions.", "",
        "## Reference (robust triangulation of all views)", "",
        f"- re-projection error over the views each point used: median "
        f"{tri['median_px']:.1f} px, mean {tri['mean_px']:.1f} px (plain confidence-weighted "
        f"DLT of all views, no rejection: median {np.nanmedian(plain.view_errors[plain.used]):.1f}"
        f" px, mean {np.nanmean(plain.view_errors[plain.used]):.1f} px)",
        f"- views used: {100 * tri['views_used_fraction']:.0f} % of the view-landmark "
        f"detections; points triangulated: {100 * tri['points_triangulated_fraction']:.1f} %",
        f"- lowest foot landmark (heels, toes) per frame, median height above the lab floor: "
        f"{1000 * tri['foot_height_median_m']:.0f} mm (lab frame z up, floor z = 0)",
        f"- camera heights: {', '.join(f'{h:.2f}' for h in ref.camera_heights)} m", "",
        "## 2d (pixels; reference from the other three views)", "",
        "| view | frames | person height px | median | mean | median in-sample | sigma/coord"
        " | white | drift | bias x, y | outliers % | leg swaps % | arm swaps % |",
        "|" + "---|" * 13, *[fmt(r) for r in rows2d],
        fmt(("all", sum(e.frames for e in errors), p["person_height_px"], p["err2d_median_px"],
             p["err2d_mean_px"], p["err2d_in_sample_median_px"], p["sigma2d_px"],
             p["sigma2d_white_px"], p["sigma2d_drift_px"], "", 100 * p["outlier_rate"],
             100 * p["swap_rate_legs"], 100 * p["swap_rate_arms"])), "",
        f"Scaled to a 1080 px tall image with the same framing (x 1080/{image_h}): median "
        f"{p['err2d_median_px'] * 1080 / image_h:.1f} px, "
        f"sigma {p['sigma2d_px'] * 1080 / image_h:.1f} px per coordinate. "
        f"As a fraction of the person's image height: median "
        f"{100 * p['err2d_median_px'] / p['person_height_px']:.2f} %, sigma "
        f"{100 * p['sigma2d_px'] / p['person_height_px']:.2f} %.", "",
        "The in-sample error is biased low (the view pulls the triangulation towards itself) "
        "and the leave-one-out error high (a three-view reference is noisier, and here it "
        "keeps more of cam02's left/right swaps); MediaPipe's own error lies between the two.",
        "",
        "## 3d (mm; world landmarks vs the four-view reference, hip-centred, camera axes)", "",
        "MPJPE and MPJPE-PA on the project's 21 joints as `physpose.metrics` computes them; "
        "the other columns on the 33 landmarks (hands and face included). Scale: RMS radius "
        "of MediaPipe's body over the reference's; depth scale: least-squares factor from the "
        "reference's hip-relative camera-z to MediaPipe's; depth predictor: the same the other "
        "way round, the factor on MediaPipe's depth that best predicts the reference's; "
        "depth corr: their uncentred correlation (the cosine between them).", "",
        "| view | MPJPE (21 joints) | MPJPE-PA | 33 landmarks mean | median | RMS x / y / z | "
        "bias x / y / z | scale | depth scale | depth predictor | depth corr |",
        "|" + "---|" * 11, *[fmt(r) for r in rows3d],
        fmt(("all", p["err3d_joints_mm"], p["err3d_joints_pa_mm"], p["err3d_mean_mm"],
             p["err3d_median_mm"], "", "", p["scale_ratio"], p["depth_scale_ratio"],
             p["depth_predictor"], p["depth_correlation"])), "",
        "## Frame of the world landmarks", "",
        "The 33-landmark mean error above, with MediaPipe's landmarks taken in camera axes, "
        "beside the same with them taken in the frame of the viewing ray through the detected "
        "hips (z along that ray) and turned into camera axes by that ray (what the kinematic "
        "fit and the detector simulator assume). Difference: mean +- standard error over the "
        "frames of the per-frame difference.", "",
        "| view | ray off the optical axis (deg) | camera axes | ray frame | difference |",
        "|" + "---|" * 5,
        *[fmt((e.view, e.ray_angle_deg, e.err3d_mean_mm, e.err3d_ray_mean_mm,
               f"{e.err3d_ray_mean_mm - e.err3d_mean_mm:+.1f} +- {e.err3d_ray_diff_se_mm:.1f}"))
          for e in errors], "",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m physpose.multiview.detector_error",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("folder", nargs="?", type=Path, default=pose2sim_demo_dir())
    parser.add_argument("--fps", type=float, default=30.0, help="observe rate, Hz")
    parser.add_argument("--out", type=Path, help="markdown file to write (default: print)")
    args = parser.parse_args(argv)
    ref = build_multiview_reference(args.folder, ReferenceConfig(
        observe=ObserveConfig(target_fps=args.fps)))
    command = shlex.join(["python", "-m", "physpose.multiview.detector_error",
                          *(sys.argv[1:] if argv is None else argv)])
    text = render_markdown(ref, detector_errors(ref), command)
    if args.out:
        args.out.write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
