"""Left/right swap repair: share of frames whose labels the repair leaves wrong, per limb group.

The detector simulator swaps the legs, the arms or the whole body for a few frames at a time and
records where (`SimulatedCapture.swapped`). This runs the kinematic fit's repair
(`kinematics.swaps.swap_paths`) on each motion-capture clip under several noise seeds and camera
azimuths, and counts the valid frames whose group is labelled wrongly after it, beside the
detector's own share. A run "fails" when over 10 % of its frames have the legs wrong (a false
swap lasting a stride or more, which the fit follows). Without --mocap, the shared clips are
used; absent those, it exits with a message. Usage:

    uv run python benchmarks/bench_swaps.py --out out/bench_swaps.json \
        [--mocap FILE ...] [--seeds 8] [--azimuth 0 --azimuth 30 ...]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from physpose.benchmark.material import crop_mocap
from physpose.detector_sim import DetectorSimConfig, simulate_detections
from physpose.joints import LANDMARK_INDEX
from physpose.kinematics import camera as cam
from physpose.kinematics.config import KinematicConfig
from physpose.kinematics.evidence import gather_evidence
from physpose.kinematics.swaps import GROUPS, swap_paths
from physpose.mocap import MocapClip, load_mocap
from physpose.paths import shared_data_dir

_SHARED = ("cmu_amc/*.amc", "cmu_bvh/*.bvh", "deepmimic/humanoid3d_*.txt")
_MARKER = {"legs": "left_knee", "arms": "left_elbow", "trunk": "left_hip"}  # one of each group
FAIL_SHARE = 0.10


def _clips(given: list[Path]) -> list[Path]:
    if given:
        return given
    root = shared_data_dir() / "mocap"
    return sorted(p for pattern in _SHARED for p in root.glob(pattern))


def _run(motion: MocapClip, seed: int, azimuth: float, cfg: KinematicConfig
         ) -> dict[str, dict]:
    capture = simulate_detections(motion, DetectorSimConfig(seed=seed, azimuth_deg=azimuth))
    obs = capture.observations
    K = cam.intrinsics(obs.image_size, cam.focal_from_fov(obs.image_size,
                                                         cfg.camera.diagonal_fov_deg))
    ev = gather_evidence(obs, K, cfg.pose.min_confidence, cfg.pose.ray_aligned_world)
    repaired = swap_paths(ev)
    valid = max(int(ev.valid.sum()), 1)
    out = {}
    for group in GROUPS:
        truth = capture.swapped[:, LANDMARK_INDEX[_MARKER[group]]] & ev.valid
        out[group] = {"detector": float(truth.sum() / valid),
                      "repaired": float(((repaired[group] ^ truth) & ev.valid).sum() / valid)}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--mocap", type=Path, action="append", default=[])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--azimuth", type=float, action="append", default=[])
    args = parser.parse_args()
    clips = _clips(args.mocap)
    if not clips:
        sys.exit(f"no motion-capture clips: pass --mocap, or put the shared material at "
                 f"{shared_data_dir() / 'mocap'}")
    azimuths = args.azimuth or [0.0, 30.0, 75.0, 150.0]
    cfg = KinematicConfig.preset("SO+GT")
    rows = []
    for path in clips:
        motion = crop_mocap(load_mocap(path, target_fps=25.0), 4.0)   # once per clip
        runs = [_run(motion, seed, az, cfg) for seed in range(args.seeds) for az in azimuths]
        legs = np.array([r["legs"]["repaired"] for r in runs])
        row = {"clip": path.stem, "runs": len(runs),
               "legs_failed_runs": int((legs > FAIL_SHARE).sum())}
        for group in GROUPS:
            for kind in ("detector", "repaired"):
                row[f"{group}_{kind}"] = float(np.mean([r[group][kind] for r in runs]))
        rows.append(row)
        print(f"{path.stem:32s} legs wrong {100 * row['legs_repaired']:5.1f} % (detector "
              f"{100 * row['legs_detector']:4.1f}), failed runs {row['legs_failed_runs']}/"
              f"{len(runs)}; arms {100 * row['arms_repaired']:4.1f} %, trunk "
              f"{100 * row['trunk_repaired']:4.1f} %", flush=True)
    total = {f"{g}_{k}": float(np.mean([r[f"{g}_{k}"] for r in rows]))
             for g in GROUPS for k in ("detector", "repaired")}
    total["legs_failed_runs"] = int(sum(r["legs_failed_runs"] for r in rows))
    total["runs"] = int(sum(r["runs"] for r in rows))
    print("mean: " + ", ".join(f"{k} {100 * v:.2f} %" for k, v in total.items()
                               if isinstance(v, float))
          + f"; legs failed in {total['legs_failed_runs']}/{total['runs']} runs")
    doc = {"seeds": args.seeds, "azimuths_deg": azimuths, "fail_share": FAIL_SHARE,
           "clips": rows, "mean": total}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
