"""`physpose reconstruct` / `demo` / help: flags, clear errors (exit 2), summary, one end-to-end run."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from physpose.cli import SUBCOMMANDS, build_parser, main
from physpose.cli.reconstruct import (check_input, duration_note, parse_formats,
                                      pipeline_config, print_summary, restarts_line,
                                      undetected_line)
from physpose.dynamics import PRESETS
from physpose.dynamics.config import available_cores
from physpose.dynamics.objective import ObjectiveWeights
from physpose.errors import PhysposeError
from physpose.report.data import forces_summary
from synthetic_result import make_reconstruction, save_result, write_video


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    """A 2 s synthetic video, 320 x 240 at 25 fps."""
    return write_video(tmp_path_factory.mktemp("clip") / "clip.mp4", num_frames=50, fps=25.0)


def _args(*argv: str):
    return build_parser().parse_args(["reconstruct", *argv])


@pytest.mark.parametrize("argv, message", [
    (["--start", "5"], "start 5 s is outside the video (0-2.000 s)"),
    (["--start", "-1"], "outside the video"),
    (["--end", "3"], "past the end of the video (2.000 s)"),
    (["--start", "1.5", "--end", "1"], "must be after start"),
    (["--obstacle", "box:1,2"], "has 2 numbers, expected 6 or 7"),
    (["--obstacle", "sphere:0,0,0,1,1,1"], "is not a box specification"),
    (["--obstacle", "box:0,0,0,a,1,1"], "not a number"),
    (["--obstacle", "box:0,0,0,1,1,-1"], "sizes must be positive"),
    (["--export", "bvh,fbx"], "unknown export format(s) 'fbx'"),
    (["--ground-friction", "-1"], "ground friction -1.0 must be >= 0"),
    (["--ground-stiffness", "0"], "ground stiffness 0.0 must be positive"),
    (["--height", "9"], "height 9.0 m is outside"),
    (["--candidates", "0"], "--candidates 0 must be >= 1"),
    (["--searches", "-1"], "--searches -1 must be >= 1"),
    (["--search-iterations", "-1"], "--search-iterations -1 must be >= 0"),
    (["--search-iterations", "0", "--candidates", "2"],
     "--candidates 2 must be 1 with --search-iterations 0"),
    (["--search-iterations", "0", "--searches", "3"],
     "--searches 3 must be 1 with --search-iterations 0"),
    (["--balance-hz", "-1"], "--balance-hz -1.0 must be a finite number >= 0"),
    (["--restart-distance", "inf"], "--restart-distance inf must be a finite number > 0"),
    (["--refine", "-2"], "--refine -2 must be >= 0"),
    (["--threads", "0"], "--threads 0 must be >= 1"),
    (["--weight", "com=-1"], "the weight must be a number >= 0"),
    (["--weight", "com=heavy"], "the weight must be a number >= 0"),
    (["--weight", "balance=1"], "names no objective term"),
    (["--weight", "15"], "names no objective term"),
    (["--weight", "pose"], "'pose' has no value"),
    (["--fps", "1000"], "outside"),
    (["--slow-motion", "0"], "slow motion 0x is outside"),
    (["--slow-motion", "-4"], "slow motion -4x is outside"),
    (["--person", "5000,10"], "--person 5000,10 is outside the"),
    (["--person", "-10,20"], "--person -10,20 is outside the"),
    (["--person", "-.5,-3"], "--person -0.5,-3 is outside the"),
    (["--camera", "{missing}.json"], "camera file not found"),
    (["--camera", "{bad_json}"], "cannot read camera intrinsics"),
    (["--camera", "{oblong_json}"], "fx = 300 and fy = 330 px: physpose fits one focal"),
    (["--camera", "{good_json}", "--camera-name", "cam01"], "applies to a Qualisys"),
    (["--out", "{good_json}"], "exists and is not a folder"),
])
def test_bad_input_gives_a_message_and_exit_2(clip, tmp_path, capsys, argv, message):
    (tmp_path / "bad.json").write_text('{"K": [[1, 2], [3]]}')
    (tmp_path / "good.json").write_text(json.dumps({"K": [[300, 0, 160], [0, 300, 120],
                                                          [0, 0, 1]]}))
    (tmp_path / "oblong.json").write_text(json.dumps({"K": [[300, 0, 160], [0, 330, 120],
                                                            [0, 0, 1]]}))
    where = {"missing": tmp_path / "nope", "bad_json": tmp_path / "bad.json",
             "good_json": tmp_path / "good.json", "oblong_json": tmp_path / "oblong.json"}
    argv = [a.format(**where) for a in argv]
    assert main(["reconstruct", str(clip), "--out", str(tmp_path / "out"), *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "out" / "reconstruction.npz").exists()


@pytest.mark.parametrize("video, message", [
    ("nope.mp4", "file not found"), ("still.png", "this is an image"),
    ("keys.json", "keypoints file not found")])
def test_bad_video_gives_exit_2(tmp_path, capsys, video, message):
    (tmp_path / "still.png").write_bytes(b"\x89PNG")
    assert main(["reconstruct", str(tmp_path / video), "--out", str(tmp_path / "o")]) == 2
    assert message in capsys.readouterr().err


def test_time_range_on_keypoints_is_refused(tmp_path, capsys):
    keys = tmp_path / "keys.npz"
    keys.write_bytes(b"")
    assert main(["reconstruct", str(keys), "--out", str(tmp_path / "o"), "--end", "1"]) == 2
    assert "apply to videos" in capsys.readouterr().err
    assert main(["reconstruct", str(keys), "--out", str(tmp_path / "o"), "--person", "1,2"]) == 2
    assert "apply to videos" in capsys.readouterr().err
    for option in (["--fps", "10"], ["--static-camera"]):  # had been ignored
        assert main(["reconstruct", str(keys), "--out", str(tmp_path / "o"), *option]) == 2
        assert "apply to videos" in capsys.readouterr().err


def test_flags_make_the_pipeline_config():
    cfg = pipeline_config(_args("v.mp4", "--out", "o", "--preset", "paper", "--fps", "20",
                                "--start", "0.5", "--end", "2", "--trampoline",
                                "--ground-friction", "0.5", "--obstacle",
                                "box:-0.35,0,0.225,0.45,0.45,0.45,30", "--obstacle",
                                "box:1,1,0.1,0.4,0.4,0.2"))
    assert (cfg.observe.target_fps, cfg.observe.start, cfg.observe.end) == (20, 0.5, 2)
    assert cfg.slow_motion == 1.0 and cfg.footage_observe() == cfg.observe
    # Slow-motion footage: the analysis rate holds on the real clock, so the footage is
    # sampled 4x more sparsely; the time range stays in the footage's seconds.
    slow = pipeline_config(_args("v.mp4", "--out", "o", "--slow-motion", "4", "--end", "8"))
    assert slow.slow_motion == 4.0
    assert (slow.footage_observe().target_fps, slow.footage_observe().end) == (6.25, 8)
    assert pipeline_config(_args("v.mp4", "--out", "o", "--person", "12.5,40")
                           ).observe.person == (12.5, 40.0)
    assert cfg.dynamics.iterations == 2000
    assert cfg.scene.ground_friction == 0.5
    assert cfg.scene.ground_stiffness_damping() == pytest.approx((150.0, 1.5))
    assert len(cfg.scene.obstacles) == 2
    assert cfg.scene.obstacles[0].yaw == pytest.approx(np.radians(30))
    default = pipeline_config(_args("v.mp4", "--out", "o"))
    assert default.scene.obstacles == () and default.scene.ground_solref == (0.01, 1.0)
    assert default.observe.use_cache and default.kinematics.use_cache
    fresh = pipeline_config(_args("v.mp4", "--out", "o", "--no-cache"))
    assert not (fresh.observe.use_cache or fresh.kinematics.use_cache)
    stiff = pipeline_config(_args("v.mp4", "--out", "o", "--ground-stiffness", "400"))
    assert stiff.scene.ground_stiffness_damping() == pytest.approx((400.0, 40.0))
    # A friction alone keeps the floor's contact; the trampoline is not given a stiffness.
    slippery = pipeline_config(_args("v.mp4", "--out", "o", "--ground-friction", "0.3"))
    assert slippery.scene.ground_solref == default.scene.ground_solref
    with pytest.raises(PhysposeError, match="--trampoline sets the floor's stiffness"):
        pipeline_config(_args("v.mp4", "--out", "o", "--trampoline", "--ground-damping", "9"))
    assert default.dynamics.candidates == 1
    assert pipeline_config(_args("v.mp4", "--out", "o", "--candidates", "3")
                           ).dynamics.candidates == 3
    assert pipeline_config(_args("v.mp4", "--out", "o", "--searches", "2")
                           ).dynamics.searches == 2
    assert default.dynamics.iterations == 30
    assert pipeline_config(_args("v.mp4", "--out", "o", "--search-iterations", "0")
                           ).dynamics.iterations == 0
    assert pipeline_config(_args("v.mp4", "--out", "o", "--preset", "paper",
                                 "--search-iterations", "50")).dynamics.iterations == 50
    assert default.auto_support
    assert not pipeline_config(_args("v.mp4", "--out", "o", "--no-auto-support")).auto_support
    assert not default.dynamics.balance.enabled
    assert default.dynamics.place_stretches
    assert not pipeline_config(_args("v.mp4", "--out", "o", "--no-place-stretches")
                               ).dynamics.place_stretches
    assert pipeline_config(_args("v.mp4", "--out", "o", "--balance-hz", "0.5")
                           ).dynamics.balance.frequency == 0.5
    assert pipeline_config(_args("v.mp4", "--out", "o", "--refine", "3")
                           ).dynamics.refine.iterations == 3
    assert default.dynamics.nthread == available_cores()
    assert pipeline_config(_args("v.mp4", "--out", "o", "--threads", "3")).dynamics.nthread == 3
    assert not pipeline_config(_args("v.mp4", "--out", "o", "--refine", "0")
                               ).dynamics.refine.enabled
    assert default.dynamics.reset_distance == 0.15
    assert pipeline_config(_args("v.mp4", "--out", "o", "--restart-distance", "0.25")
                           ).dynamics.reset_distance == 0.25
    with pytest.raises(PhysposeError, match="--restart-distance 0.0 must be a finite number > 0"):
        pipeline_config(_args("v.mp4", "--out", "o", "--restart-distance", "0"))
    assert default.dynamics.weights == PRESETS["fast"].weights
    paper = pipeline_config(_args("v.mp4", "--out", "o", "--weight", "com=15",
                                  "--weight", "POSE = 0.5", "--weight", "swing=0")
                            ).dynamics.weights
    assert paper == ObjectiveWeights()  # the paper's weights
    no_tv = pipeline_config(_args("v.mp4", "--out", "o", "--weight", "tv=0")).dynamics.weights
    assert no_tv == dataclasses.replace(PRESETS["fast"].weights, tv=0.0)


def test_the_seconds_to_analyse_are_known_before_observing(clip):
    config = pipeline_config(_args(str(clip), "--out", "o", "--start", "0.4", "--end", "1.6"))
    size, seconds = check_input(clip, config)
    assert size == (320, 240) and seconds == pytest.approx(1.2)


def test_a_long_clip_is_told_what_the_physics_will_cost_beforehand():
    assert duration_note(29.0, "fast") is None
    note = duration_note(180.0, "fast")
    assert note.startswith("180 s of video") and "about 30-108 min" in note
    assert "about 90 min to 5.4 h" in duration_note(180.0, "fast", candidates=3)
    # The paper preset costs 43 min per second of video: told for any clip.
    assert "about 86 min" in duration_note(2.0, "paper")
    # --start/--end do not cut a keypoints file.
    assert "--start" not in duration_note(60.0, "fast", keypoints=True)


def test_export_formats():
    assert parse_formats("bvh, GLB,csv") == ("bvh", "glb", "csv")
    assert parse_formats("none") == () == parse_formats("")
    with pytest.raises(PhysposeError, match="'fbx'"):
        parse_formats("fbx")


def test_summary_lists_metrics_files_and_times(tmp_path, capsys):
    folder = save_result(tmp_path, num_frames=5)
    metrics = {"kinematic": {"float_pct": 12.5}, "physics": {"float_pct": 1.0}}
    print_summary(make_reconstruction(num_frames=5), folder,
                  {"report": folder / "report.html"}, metrics,
                  {"observe": 1.0, "kinematics": 2.0, "dynamics": 3.5})
    out = capsys.readouterr().out
    assert "5 frames at 25 fps" in out and "physics and kinematic motion" in out
    assert "float (% frames)" in out and "12.5" in out
    assert "report.html" in out and "reconstruction.npz" in out
    assert "dynamics 3.5 s" in out and "total 6.5 s" in out
    assert "into the video" not in out  # a result that does not record where it lies
    # One that does says where its frames are in the video, once (the tables carry it too).
    rec = make_reconstruction(num_frames=5, meta={"frame_indices": [24, 26, 29, 31, 34],
                                                  "timestamps": [0.4, 0.44, 0.48, 0.52, 0.56]})
    print_summary(rec, folder, {}, None, {})
    assert "they are 0.40-0.56 s (frames 24-34) into the video; the times below count from " \
           "the first of them" in capsys.readouterr().out
    # The simulated forces in one line.
    line = forces_summary(make_reconstruction(num_frames=5))
    assert line.startswith("peak vertical ground reaction force")
    assert f"physics: {line} (forces.csv" in out


def test_summary_says_where_the_physics_restarted_from_the_estimate(capsys):
    windows = [{"frames": [0, 25], "reset_after": False}, {"frames": [10, 35], "reset_after": True},
               {"frames": [22, 47], "reset_after": False}, {"frames": [32, 49]}]
    recon = make_reconstruction(num_frames=5, meta={"dynamics": {"windows": windows}})
    assert recon.restarts == [22]  # read from the window records (older results)
    assert "restarted from the kinematic estimate once" in restarts_line(recon)
    assert "frame 22 (0.88 s)" in restarts_line(recon)
    recon = recon.replace(meta={"dynamics": {"windows": windows, "restarts": [22, 40]}})
    assert recon.restarts == [22, 40]
    assert "2 times" in restarts_line(recon) and "frames 22 (0.88 s), 40 (1.60 s)" \
        in restarts_line(recon)
    calm = recon.replace(meta={"dynamics": {"windows": windows[:1], "restarts": []}})
    print_summary(calm, Path("out"), {}, None, {})
    assert "one continuous simulation (no restarts)" in capsys.readouterr().out
    print_summary(recon.replace(joints_physics=None, landmarks_physics=None, qpos_physics=None),
                  Path("out"), {}, None, {})
    assert "restart" not in capsys.readouterr().out  # no physics, nothing to say


def test_summary_says_where_no_person_was_detected(capsys):
    recon = make_reconstruction(num_frames=30)
    assert recon.undetected_runs == [] and undetected_line(recon) is None
    kp = recon.keypoints2d.copy()
    kp[0, :, 2] = 0          # one frame at the start
    kp[10:20, :, 2] = 0      # a run in the middle
    kp[12, 5, 2] = 0.9       # one landmark seen: the frame is observed
    recon = recon.replace(keypoints2d=kp)
    assert recon.undetected_runs == [(0, 0), (10, 11), (13, 19)]
    print_summary(recon, Path("out"), {}, None, {})
    out = capsys.readouterr().out
    assert "no person detected in 10 of 30 frames, at 0 (0.00 s), 10-11 (0.40-0.48 s)," in out
    assert "inferred from the frames around them" in out


@pytest.mark.parametrize("command", [None, *SUBCOMMANDS])
def test_every_help_is_complete(command, capsys):
    with pytest.raises(SystemExit) as done:
        main(["--help"] if command is None else [command, "--help"])
    assert done.value.code == 0
    text = capsys.readouterr().out
    assert "usage: physpose" in text and "-h, --help" in text
    if command is None:
        assert all(name in text for name in SUBCOMMANDS)
    else:
        described = [a for a in build_parser()._subparsers._group_actions[0].choices[command]
                     ._actions if a.dest != "help"]
        assert all(a.help for a in described), [a.dest for a in described if not a.help]


@pytest.mark.slow
def test_reconstruct_end_to_end_on_a_short_clip(pose2sim_demo, tmp_path, capsys):
    video = pose2sim_demo / "videos" / "cam01.mp4"
    out = tmp_path / "r"
    assert main(["reconstruct", str(video), "--out", str(out), "--end", "0.8",
                 "--export", "csv", "--camera", str(pose2sim_demo / "calibration" /
                                                    "Calib.qca.txt")]) == 0
    text = capsys.readouterr().out
    assert "MPJPE-2d vs detections (px)" in text and "time per stage" in text
    for name in ("reconstruction.npz", "config.json", "metrics.json", "report.html",
                 "overlay.mp4", "overlay.png", "joints.csv"):
        assert (out / name).stat().st_size > 0, name
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics) == {"kinematic", "physics"}
    assert metrics["kinematic"]["mpjpe_2d_px"] < 30.0


@pytest.mark.parametrize("argv, message", [
    (["observe", "{missing}.mp4", "--out", "{out}"], "file not found"),
    (["fit", "{missing}.mp4", "--out", "{out}"], "file not found"),
    (["body", "--height", "9", "--out", "{out}"], "outside 0.5-2.5 m"),
    (["export", "{missing}", "-f", "csv"], "result folder not found"),
])
def test_other_subcommands_refuse_bad_input(tmp_path, capsys, argv, message):
    where = {"missing": tmp_path / "nope", "out": tmp_path / "out"}
    assert main([a.format(**where) for a in argv]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_unknown_export_format_is_a_usage_error(tmp_path, capsys):
    with pytest.raises(SystemExit) as done:
        main(["export", str(tmp_path), "-f", "fbx"])
    assert done.value.code == 2 and "invalid choice: 'fbx'" in capsys.readouterr().err


def test_a_person_that_is_not_a_point_is_a_usage_error(tmp_path, capsys):
    with pytest.raises(SystemExit) as done:
        main(["reconstruct", "v.mp4", "--out", str(tmp_path), "--person", "left"])
    assert done.value.code == 2 and "'left' is not X,Y in pixels" in capsys.readouterr().err


def test_demo_still_writes_the_kinematic_outputs_when_dynamics_fails(tmp_path, monkeypatch,
                                                                     capsys):
    import physpose.cli.demo as demo
    import physpose.pipeline as pipeline

    def failing_reconstruct(*args, **kwargs):
        raise RuntimeError("simulated blow-up")

    def kinematic_only(obs, config, out):
        rec = make_reconstruction(num_frames=5, physics=False)
        rec.save(out / "reconstruction.npz")
        return rec

    monkeypatch.setattr(demo, "ensure_pose2sim_demo", lambda: tmp_path)
    monkeypatch.setattr(demo, "load_input", lambda video, config, K: None)
    monkeypatch.setattr(pipeline, "reconstruct", failing_reconstruct)
    monkeypatch.setattr(demo, "_kinematic_only", kinematic_only)
    out = tmp_path / "demo"
    out.mkdir()
    assert main(["demo", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "physics stage FAILED (RuntimeError: simulated blow-up)" in text
    assert "kinematic motion only" in text and "report.html" in text
    assert set(json.loads((out / "metrics.json").read_text())) == {"kinematic"}
    assert (out / "overlay.mp4").stat().st_size > 0 and (out / "motion.bvh").is_file()
