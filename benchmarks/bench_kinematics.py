"""Kinematic-fit runtime: seconds per frame of `fit_kinematics` per variant, cold and warm.

"Cold" is the first fit of a clip length in the process (it includes JAX's compilation of the
objective), "warm" a second fit of another clip of the same padded length (compiled code is
reused). Clips: 100-frame motion-capture clips through the detector simulator (shared data) and
a synthetic walk when those are absent. Usage:

    uv run python benchmarks/bench_kinematics.py --out out/bench_kinematics.json \
        [--variant SO+GT] [--frames 100]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from physpose.benchmark.runner import machine_description
from physpose.kinematics import KinematicConfig, fit_kinematics
from physpose.paths import shared_data_dir

_CLIPS = ("cmu_bvh/scaled_131_01.bvh", "cmu_amc/charleston1.amc", "cmu_bvh/scaled_131_03.bvh")


def _mocap_observations(frames: int):
    from physpose.detector_sim import DetectorSimConfig, simulate_detections
    from physpose.mocap import load_mocap

    for rel in _CLIPS:
        path = shared_data_dir() / "mocap" / rel
        if not path.is_file():
            print(f"skipped {path} (absent)", file=sys.stderr)
            continue
        capture = simulate_detections(load_mocap(path, 25.0), DetectorSimConfig(seed=0))
        obs = capture.observations
        n = min(frames, obs.num_frames)
        per_frame = ("timestamps", "keypoints2d", "detected", "interpolated", "world_landmarks",
                     "frame_indices")
        yield path.name, obs.replace(**{k: getattr(obs, k)[:n] for k in per_frame
                                        if getattr(obs, k) is not None}), capture.camera_K


def _synthetic_observations(frames: int):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from test_kinematics_fixtures import synthetic_clip

    for seed in range(2):
        clip = synthetic_clip(frames=frames, noise_px=3.0, noise_3d=0.04, seed=seed)
        yield f"synthetic_walk_{seed}", clip.observations, clip.K


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--variant", action="append", default=[])
    parser.add_argument("--frames", type=int, default=100)
    args = parser.parse_args()
    variants = args.variant or ["SO+GT"]
    clips = list(_mocap_observations(args.frames)) or list(_synthetic_observations(args.frames))
    rows = []
    for variant in variants:
        config = KinematicConfig.preset(variant, use_cache=False)
        for i, (name, obs, K) in enumerate(clips):
            load = os.getloadavg()[0]
            start = time.perf_counter()
            fit = fit_kinematics(obs, config, camera_K=K)
            seconds = time.perf_counter() - start
            rows.append({"variant": variant, "clip": name, "frames": obs.num_frames,
                         "run": "cold" if i == 0 else "warm", "seconds": seconds,
                         "seconds_per_frame": seconds / obs.num_frames,
                         "stages_s": fit.timings, "load_average": load})
            print(f"{variant:6s} {name:24s} {rows[-1]['run']}: {seconds:6.1f} s, "
                  f"{rows[-1]['seconds_per_frame']:.3f} s/frame (load {load:.1f})", flush=True)
    warm = [r["seconds_per_frame"] for r in rows if r["run"] == "warm"]
    doc = {"machine": machine_description(),
           "rows": rows, "warm_seconds_per_frame_mean": float(np.mean(warm)) if warm else None}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
