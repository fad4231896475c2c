"""`physpose demo`: the whole pipeline on the built-in pose2sim clip, with every output."""

from __future__ import annotations

import argparse
import sys
import time
import traceback
from pathlib import Path

from physpose.cli.reconstruct import finish, load_input, print_summary
from physpose.demo_data import ensure_pose2sim_demo
from physpose.errors import PhysposeError
from physpose.outputs import DEFAULT_FORMATS
from physpose.paths import check_output_folder
from physpose.pipeline import RECONSTRUCTION_FILE, PipelineConfig

DEMO_VIEW = "videos/cam01.mp4"  # the view the demo reconstructs (of the four calibrated ones)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo", help="reconstruct the built-in demo clip and write the report, overlay, exports",
        description="Fetch the pose2sim demo clip if needed and run the whole pipeline (fast "
                    "preset) on its first view: observe, kinematic fit, body, physics "
                    "optimisation, then metrics, report.html, overlay.mp4 and the exports "
                    "(BVH, glTF, joints and forces CSV) and overlay.png in --out. Takes a "
                    "few minutes on 2 cores.")
    p.add_argument("--out", type=Path, default=Path("out/demo"), metavar="DIR",
                   help="output folder (default: out/demo)")
    p.add_argument("--no-cache", action="store_true",
                   help="recompute every stage (default: reuse cached observe/kinematic "
                        "results and finished optimisation windows)")
    p.set_defaults(func=_run)


def _kinematic_only(obs, config: PipelineConfig, out: Path):
    """The kinematic result written as reconstruction.npz, when the dynamics stage failed."""
    from physpose.kinematics.fit import fit_kinematics, stderr_log  # noqa: PLC0415
    from physpose.kinematics.variants import reconstruction_of  # noqa: PLC0415

    recon = reconstruction_of(fit_kinematics(obs, config.kinematics, log=stderr_log,
                                             progress=True), obs)
    recon.save(out / RECONSTRUCTION_FILE)
    return recon


def _run(args: argparse.Namespace) -> int:
    from physpose.pipeline import reconstruct  # noqa: PLC0415 (heavy imports)

    start = time.perf_counter()
    check_output_folder(args.out)
    video = ensure_pose2sim_demo() / DEMO_VIEW
    print(f"demo input: {video}", flush=True)
    config = PipelineConfig.preset("fast")
    if args.no_cache:
        config = config.without_cache()
    timings: dict[str, float] = {}
    clock = time.perf_counter()
    obs = load_input(video, config, None)
    timings["observe"] = time.perf_counter() - clock
    try:
        recon = reconstruct(obs, args.out, config, resume=not args.no_cache, progress=True)
        timings.update({k: v for k, v in recon.meta.get("timings_s", {}).items()
                        if k != "observe"})
    except PhysposeError:
        raise  # the user's to fix (a path, the input), not a failure of the physics
    except Exception as exc:  # noqa: BLE001 (reported in full; the kinematic result is kept)
        traceback.print_exc(file=sys.stderr)
        print(f"\ndemo: the physics stage FAILED ({type(exc).__name__}: {exc}); writing the "
              "kinematic result only", flush=True)
        clock = time.perf_counter()
        recon = _kinematic_only(obs, config, args.out)
        timings["kinematics"] = time.perf_counter() - clock
    written, metrics = finish(args.out, DEFAULT_FORMATS, report=True, overlay=True,
                              timings=timings)
    print_summary(recon, args.out, written, metrics, timings)
    print(f"\ndemo finished in {time.perf_counter() - start:.1f} s. Open the report in a "
          f"browser:\n  {(args.out / 'report.html').resolve()}")
    return 0
