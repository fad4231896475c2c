"""Observe-stage throughput: frames/s of `observe()`, its decode vs MediaPipe time split, and
the camera-motion step's time (`camera_motion.estimate_camera_motion`, a second decoding pass).

Clips: the four pose2sim demo views, ../shared/data/video/taichi_static.mp4 and
running_track_panning.mp4 (each skipped with a message when absent). Usage:

    uv run python benchmarks/bench_observe.py --out out/bench_observe.json [--fps 25]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

from physpose.benchmark.runner import machine_description
from physpose.camera_motion import estimate_camera_motion
from physpose.demo_data import demo_videos
from physpose.observe import ObserveConfig, PoseDetector, observe
from physpose.paths import shared_data_dir
from physpose.video import plan_frames, probe, read_frames


def split_pass(video: Path, cfg: ObserveConfig) -> dict:
    """One pass over the planned frames timing decoding and MediaPipe separately (seconds)."""
    info = probe(video)
    plan = plan_frames(info, cfg.target_fps, cfg.start, cfg.end)
    t0 = time.perf_counter()
    detector = PoseDetector(cfg)
    load = time.perf_counter() - t0
    decode = detect = 0.0
    frames = found = 0
    with detector:
        it = read_frames(info, plan.indices)
        while True:
            t0 = time.perf_counter()
            item = next(it, None)
            t1 = time.perf_counter()
            if item is None:
                break
            found += detector.detect(item[1]) is not None
            decode += t1 - t0
            detect += time.perf_counter() - t1
            frames += 1
    return {"video": str(video), "source_fps": info.fps, "source_frames": info.frame_count,
            "size": list(info.image_size), "fps": plan.fps, "frames": frames,
            "detection_rate": found / frames, "model_load_s": load, "decode_s": decode,
            "mediapipe_s": detect, "decode_ms_per_frame": 1e3 * decode / frames,
            "mediapipe_ms_per_frame": 1e3 * detect / frames}


def bench(video: Path, cfg: ObserveConfig) -> dict:
    row = split_pass(video, cfg)
    t0 = time.perf_counter()
    obs = observe(video, cfg, progress=False)
    row["observe_s"] = time.perf_counter() - t0
    row["observe_frames_per_s"] = obs.num_frames / row["observe_s"]
    info = probe(video)
    t0 = time.perf_counter()
    motion = estimate_camera_motion(info, plan_frames(info, cfg.target_fps, cfg.start, cfg.end),
                                    obs)
    row["camera_motion_s"] = time.perf_counter() - t0
    row["camera_motion_share"] = row["camera_motion_s"] / row["observe_s"]
    row["camera_motion"] = motion.kind
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="JSON file for the results")
    parser.add_argument("--fps", type=float, default=25.0, help="analysis rate, Hz")
    args = parser.parse_args()
    cfg = ObserveConfig(target_fps=args.fps, use_cache=False)
    clips = [v for v in demo_videos() if v.is_file()]
    if not clips:
        print("pose2sim demo absent: run `make data` (skipping those clips)")
    for name in ("taichi_static.mp4", "running_track_panning.mp4"):
        video = shared_data_dir() / "video" / name
        if video.is_file():
            clips.append(video)
        else:
            print(f"{video} absent: skipping it")
    rows = [bench(v, cfg) for v in clips]
    print(f"{'clip':24s} {'size':>10s} {'frames':>6s} {'det%':>5s} {'decode ms':>9s} "
          f"{'mp ms':>6s} {'load s':>6s} {'observe f/s':>11s} {'camera %':>8s} {'camera':>8s}")
    for r in rows:
        name = f"{Path(r['video']).parent.name[:8]}/{Path(r['video']).name}"
        print(f"{name:24s} {'x'.join(map(str, r['size'])):>10s} {r['frames']:6d} "
              f"{100 * r['detection_rate']:5.1f} {r['decode_ms_per_frame']:9.1f} "
              f"{r['mediapipe_ms_per_frame']:6.1f} {r['model_load_s']:6.2f} "
              f"{r['observe_frames_per_s']:11.1f} {100 * r['camera_motion_share']:8.1f} "
              f"{r['camera_motion']:>8s}")
    meta = {"machine": machine_description(), "python": platform.python_version(),
            "target_fps": args.fps, "note": "decode = grab+retrieve of the planned frames "
            "(skipped frames included); mediapipe = Pose.process incl. BGR->RGB and mask resize; "
            "camera % = the camera-motion step's time over the whole observe() time (which "
            "includes it)"}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"meta": meta, "clips": rows}, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
