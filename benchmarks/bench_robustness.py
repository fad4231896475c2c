"""Robustness sweep: the whole pipeline on altered copies of the shared real videos.

Each source segment is re-encoded as it is ("original") and altered in the ways users' footage
differs: mirrored, cropped to portrait, low resolution, half the frame rate (from a still
camera and from a travelling one), dark and noisy, the person hidden for 10 frames, one second
only, every frame shown twice at 60 fps. Every copy runs through `pipeline.reconstruct` with
the default preset. The sweep records whether it finished (an exception is recorded and the
sweep goes on), the physics' restarts, the frames of windows in which no simulated sample
stayed valid, its time, and the image error and foot skate of both motions. Image errors are
also given as a percentage of the person's height in the image, so that resolutions compare.

Needs ../shared/data/video (each source skipped with a message when absent). The 12 copies
took 12 min of reconstruction on a 2-core machine (stop 81). Usage:

    uv run python benchmarks/bench_robustness.py --out out/robustness [--only taichi_mirror]

Exits 1 when a variant failed.
"""

from __future__ import annotations

import argparse
import platform
import time
import traceback
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from physpose.benchmark.runner import machine_description
from physpose.benchmark.report import results_json
from physpose.metrics import fallen
from physpose.outputs import motion_metrics
from physpose.paths import shared_data_dir
from physpose.pipeline import PipelineConfig, reconstruct

Frames = list[np.ndarray]
# name -> (file in shared/data/video, start s, duration s)
SOURCES = {"taichi": ("taichi_static.mp4", 2.0, 3.0),
           "road": ("walking_road_moving_camera.mp4", 0.0, 3.0),
           "track": ("running_track_panning.mp4", 0.0, 2.0)}


def _hide_person(frames: Frames) -> Frames:
    """Black out frames 30-39 from a third of the width to 10 px past two thirds (where the
    tai chi player stands)."""
    out = [f.copy() for f in frames]
    for f in out[30:40]:
        w = f.shape[1]
        f[:, w // 3:2 * w // 3 + 10] = 0
    return out


def _dark_noisy(frames: Frames) -> Frames:
    rng = np.random.default_rng(0)
    return [np.clip(f * 0.3 + rng.normal(0.0, 6.0, f.shape), 0, 255).astype(np.uint8)
            for f in frames]


def _portrait(frames: Frames) -> Frames:
    """A 9:16 crop about the image's centre."""
    h, w = frames[0].shape[:2]
    half = (9 * h // 16) // 2
    return [f[:, w // 2 - half:w // 2 + half].copy() for f in frames]


# name -> (source, transform of (frames, fps))
VARIANTS: dict[str, tuple[str, Callable[[Frames, float], tuple[Frames, float]]]] = {
    "taichi_original": ("taichi", lambda f, fps: (f, fps)),
    "taichi_mirror": ("taichi", lambda f, fps: ([x[:, ::-1].copy() for x in f], fps)),
    "taichi_portrait": ("taichi", lambda f, fps: (_portrait(f), fps)),
    "taichi_hidden_10_frames": ("taichi", lambda f, fps: (_hide_person(f), fps)),
    "taichi_one_second": ("taichi", lambda f, fps: (f[:round(fps)], fps)),
    "taichi_half_rate": ("taichi", lambda f, fps: (f[::2], fps / 2)),
    "road_original": ("road", lambda f, fps: (f, fps)),
    "road_320x180": ("road", lambda f, fps: (
        [cv2.resize(x, (320, 180), interpolation=cv2.INTER_AREA) for x in f], fps)),
    "road_half_rate": ("road", lambda f, fps: (f[::2], fps / 2)),
    "road_dark_noisy": ("road", lambda f, fps: (_dark_noisy(f), fps)),
    "track_original": ("track", lambda f, fps: (f, fps)),
    "track_doubled_60fps": ("track", lambda f, fps: ([x for x in f for _ in (0, 1)], 2 * fps)),
}


def read_segment(path: Path, start: float, duration: float) -> tuple[Frames, float]:
    cap = cv2.VideoCapture(str(path))
    fps = cap.get(cv2.CAP_PROP_FPS)
    frames, index = [], 0
    while True:
        ok, image = cap.read()
        if not ok or index >= (start + duration) * fps:
            break
        if index >= start * fps:
            frames.append(image)
        index += 1
    cap.release()
    return frames, fps


def write_video(path: Path, frames: Frames, fps: float) -> None:
    h, w = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h))
    for image in frames:
        writer.write(image)
    writer.release()


def person_height_px(keypoints2d: np.ndarray) -> float:
    """Median over frames of the vertical extent of the confident landmarks (px)."""
    sure = keypoints2d[..., 2] >= 0.5
    y = np.where(sure, keypoints2d[..., 1], np.nan)
    extent = np.nanmax(y, axis=1) - np.nanmin(y, axis=1)
    return float(np.nanmedian(extent[sure.sum(axis=1) >= 2]))


def run_variant(name: str, video: Path, folder: Path) -> dict:
    """One copy through the pipeline and scored; a failure anywhere is recorded, not raised."""
    row: dict = {"variant": name, "video": str(video)}
    try:
        row.update(_reconstruct_and_score(video, folder))
    except Exception as error:  # noqa: BLE001 (the sweep records any failure and goes on)
        row.update(error=f"{type(error).__name__}: {error}",
                   traceback=traceback.format_exc(limit=6))
    return row


def _reconstruct_and_score(video: Path, folder: Path) -> dict:
    row: dict = {}
    start = time.perf_counter()
    rec = reconstruct(video, folder, PipelineConfig(), resume=False, progress=False)
    row["time_s"] = time.perf_counter() - start
    row.update(frames=rec.num_frames, fps=rec.fps, restarts=len(rec.restarts),
               dynamics_s_per_s=rec.meta["timings_s"]["dynamics"] * rec.fps / rec.num_frames)
    height = person_height_px(rec.keypoints2d)
    row["person_height_px"] = height
    for motion in ("kinematic", "physics"):
        m = motion_metrics(rec, motion)
        row[motion] = {"mpjpe_2d_px": m.get("mpjpe_2d_px"),
                       "mpjpe_2d_pct_height": 100 * m.get("mpjpe_2d_px", np.nan) / height,
                       "foot_skate_pct": m["foot_skate_pct"]}
    row["physics"]["fallen_pct"] = fallen(rec.joints("physics"), rec.joints_kinematic,
                                          rec.joint_names)
    # The pipeline's own screen of windows without a valid sample (pipeline._screen_physics).
    row["physics"]["invalid_frames"] = sum(
        last - first + 1 for first, last in rec.meta["diagnostics"]["invalid_windows"])
    return row


def _cell(value, spec: str) -> str:
    return "-" if value is None or not np.isfinite(value) else spec.format(value)


def print_table(rows: list[dict]) -> None:
    print(f"{'variant':24s} {'frames':>6s} {'restarts':>8s} {'dyn s/s':>7s} "
          f"{'2d % height kin/phys':>21s} {'2d px kin/phys':>15s} {'skate % kin/phys':>17s} "
          f"{'fallen %':>8s} {'invalid frames':>14s}")
    for r in rows:
        if "error" in r:
            print(f"{r['variant']:24s} FAILED {r['error']}")
            continue
        k, p = r["kinematic"], r["physics"]
        print(f"{r['variant']:24s} {r['frames']:6d} {r['restarts']:8d} "
              f"{r['dynamics_s_per_s']:7.1f} "
              f"{_cell(k['mpjpe_2d_pct_height'], '{:.2f}'):>10s} / "
              f"{_cell(p['mpjpe_2d_pct_height'], '{:.2f}'):<8s}"
              f"{_cell(k['mpjpe_2d_px'], '{:.1f}'):>7s} / {_cell(p['mpjpe_2d_px'], '{:.1f}'):<5s}"
              f"{k['foot_skate_pct']:8.1f} / {p['foot_skate_pct']:<6.1f}"
              f"{p['fallen_pct']:8.1f} {p['invalid_frames']:14d}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True,
                        help="folder for the altered videos, each run and results.json")
    parser.add_argument("--only", nargs="+", choices=sorted(VARIANTS), metavar="VARIANT",
                        help=f"run these variants only (of {', '.join(VARIANTS)})")
    args = parser.parse_args()
    names = args.only or list(VARIANTS)
    videos = shared_data_dir() / "video"
    args.out.mkdir(parents=True, exist_ok=True)
    segments: dict[str, tuple[Frames, float]] = {}
    rows, skipped = [], []
    for name in names:
        source = VARIANTS[name][0]
        path = videos / SOURCES[source][0]
        if not path.is_file():
            skipped.append(f"{name}: {path} absent")
            print(f"skipping {name}: {path} absent (../shared/data/video)")
            continue
        if source not in segments:
            segments[source] = read_segment(path, *SOURCES[source][1:])
        if not segments[source][0]:
            skipped.append(f"{name}: no frames read from {path}")
            print(f"skipping {name}: no frames read from {path} in {SOURCES[source][1:]} s")
            continue
        frames, fps = VARIANTS[name][1](*segments[source])
        video = args.out / f"{name}.mp4"
        write_video(video, frames, fps)
        print(f"{name}: {len(frames)} frames {frames[0].shape[1]}x{frames[0].shape[0]} "
              f"at {fps:.3f} fps", flush=True)
        rows.append(run_variant(name, video, args.out / name))
    print_table(rows)
    meta = {"machine": machine_description(),
            "python": platform.python_version(), "sources": SOURCES, "skipped": skipped}
    (args.out / "results.json").write_text(results_json({"meta": meta, "rows": rows}) + "\n")
    print(f"wrote {args.out / 'results.json'}")
    raise SystemExit(1 if any("error" in r for r in rows) else 0)


if __name__ == "__main__":
    main()
