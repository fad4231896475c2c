"""The windowed optimiser on a tiny simulated clip: determinism, checkpoint/resume, both modes
and input checks."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

from physpose.body import build_body
from physpose.dynamics import TERMS, DynamicsConfig, optimize_dynamics
from physpose.dynamics import checkpoint
from physpose.dynamics import optimize as optimize_module
from physpose.dynamics.balance import BalanceGains
from physpose.dynamics.ilqr import RefineConfig
from physpose.dynamics.optimize import foot_heights, reference_motion, searched_dofs
from physpose.dynamics.search import cma_strategy, window_seed
from physpose.dynamics.spline import KnotGrid
from physpose.dynamics.synthetic import simulated_clip
from physpose.dynamics.windows import blend_weights, plan_windows
from physpose.errors import PhysposeError
from physpose.shape import BodyShape
from physpose.skeleton import DOF_NAMES

TINY = DynamicsConfig(window=0.4, overlap=0.16, popsize=4, iterations=2, knot_spacing=0.1)


@pytest.fixture(scope="module")
def clip():
    """A standing clip whose kinematic estimate carries a smooth error (so the search moves)."""
    body = build_body(BodyShape.from_height(1.7))
    fit, obs, _ = simulated_clip(body, "stand", seconds=0.8)
    t = np.arange(fit.num_frames)[:, None] / fit.fps
    qpos = fit.qpos.copy()
    qpos[:, 7:] += 0.03 * np.sin(2 * np.pi * 1.5 * t + np.arange(48)[None])
    return body, dataclasses.replace(fit, qpos=qpos), obs


def run(clip, cfg=TINY, **kwargs):
    body, fit, obs = clip
    return optimize_dynamics(body, fit, obs, cfg, progress=False, **kwargs)


def test_reference_motion_is_the_estimate_prepared_for_the_windows(clip):
    body, fit, obs = clip
    ref = reference_motion(body, fit, obs, TINY)
    assert ref.shape == fit.qpos.shape and np.isfinite(ref).all()
    # Low-passed: the estimate's 1.5 Hz hinge error passes nearly whole through 0.1 s knots,
    # so the reference stays near it (the legs of flattened standing feet move most); the
    # standing body is put on its floor.
    hinges = np.abs(ref[:, 7:] - fit.qpos[:, 7:])
    assert hinges.mean() < 0.005 and hinges.max() < 0.06
    assert np.abs(ref[:, :3] - fit.qpos[:, :3]).max() < 0.03
    assert (foot_heights(body.model, ref, body.foot_geom_ids) > -0.005).all()
    # Without the preparation steps the reference is the estimate low-passed only.
    raw = reference_motion(body, fit, obs, dataclasses.replace(TINY, ground_reference=False,
                                                               flat_stance=False))
    assert not np.allclose(raw, ref)


def test_result_shapes_and_records(clip):
    body, fit, _ = clip
    res = run(clip, checkpoints=False)
    t = fit.num_frames
    assert res.qpos.shape == (t, 55) and res.joints.shape == (t, 21, 3)
    assert res.landmarks.shape == (t, 33, 3) and res.com.shape == (t, 3)
    assert res.foot_heights.shape == (t, 2)
    assert res.ctrl.shape == (int(round((t - 1) / fit.fps / body.model.opt.timestep)), 48)
    assert len(res.windows) == len(plan_windows(t, fit.fps, 0.005, 0.4, 0.16)) >= 3
    for w in res.windows:
        assert w["evaluations"] == 1 + TINY.iterations * (TINY.popsize + 1)
        assert w["loss_final"] <= w["loss_initial"]
        assert set(w["terms_final"]) == set(TERMS)
    # The estimate's unexplained root force, per frame and per window (median over its steps).
    assert res.reference_residual.shape == (t,) and (res.reference_residual >= 0).all()
    assert all(0 <= w["reference_residual"] < 1 for w in res.windows)
    assert set(res.reference_summary()) == {"root_residual_median", "root_residual_p90"}
    # The standing body keeps its feet on the floor and stays near the true motion.
    assert np.abs(res.foot_heights).max() < 0.01
    assert np.linalg.norm(res.joints - fit.joints, axis=-1).mean() < 0.03
    # Its forces: the floor carries it on its two soles, as Newton has it frame by frame (after
    # the first frames, where the body settles onto the floor in a few steps).
    assert res.grf.shape == (t, 3, 3) and res.cop.shape == (t, 2, 3)
    assert res.torques.shape == (t, 48) and np.isfinite(res.grf).all()
    weight = body.total_mass * 9.81
    acc = np.diff(res.com[:, 2], 2) * fit.fps ** 2
    np.testing.assert_allclose(res.grf[2:-1].sum(axis=1)[:, 2],
                               body.total_mass * (acc[1:] + 9.81), atol=0.03 * weight)
    assert np.abs(res.grf[:, 2]).max() < 1e-9 and np.isfinite(res.cop).all()
    assert np.isfinite(res.torques).all() and np.abs(res.torques).max() > 1.0  # held upright


def test_window_bars_say_the_time_left_once_two_windows_are_done(clip, capsys):
    """A long clip has hundreds of windows: from the third on, each bar says the time left."""
    body, fit, obs = clip
    res = optimize_dynamics(body, fit, obs, TINY, checkpoints=False, progress=True)
    err = capsys.readouterr().err
    last = len(res.windows)
    assert last >= 3
    assert "dynamics window 1/" in err and "dynamics window 2/" in err
    assert "left)" not in err.split(f"dynamics window 3/{last}")[0]
    assert re.search(rf"dynamics window {last}/{last} \((under a minute|about .* min) left\)",
                     err)


def test_same_seed_same_result_and_another_seed_differs(clip):
    a = run(clip, checkpoints=False)
    b = run(clip, checkpoints=False)
    np.testing.assert_array_equal(a.qpos, b.qpos)
    # Every window draws its own reproducible samples from (seed, window index).
    x0 = np.zeros(10)

    def draw(seed: int, w: int) -> np.ndarray:
        return np.array(cma_strategy(x0, TINY, window_seed(seed, w)).ask())

    np.testing.assert_array_equal(draw(0, 1), draw(0, 1))
    assert not np.array_equal(draw(0, 1), draw(0, 2))
    assert not np.array_equal(draw(0, 1), draw(7, 1))


def test_searching_legs_and_trunk_keeps_the_other_targets(clip):
    res = run(clip, dataclasses.replace(TINY, search="legs_trunk"), checkpoints=False)
    init = run(clip, dataclasses.replace(TINY, iterations=0), checkpoints=False)
    kept = np.setdiff1d(np.arange(48), searched_dofs("legs_trunk"))
    assert len(kept) == 24
    np.testing.assert_allclose(res.ctrl[:, kept], init.ctrl[:, kept], atol=1e-12)


def test_without_search_iterations_the_seed_changes_nothing(clip):
    # The seed only draws CMA-ES samples; the CLI refuses candidates or side-by-side searches
    # without search iterations because of this.
    cfg = dataclasses.replace(TINY, iterations=0, tracking_start=True,
                              refine=RefineConfig(iterations=2))
    a = run(clip, dataclasses.replace(cfg, seed=0), checkpoints=False)
    b = run(clip, dataclasses.replace(cfg, seed=5), checkpoints=False)
    np.testing.assert_array_equal(a.qpos, b.qpos)
    np.testing.assert_array_equal(a.ctrl, b.ctrl)


def test_candidates_keep_the_lowest_loss_seed(clip):
    cfg = dataclasses.replace(TINY, popsize=8, iterations=6, sigma0=0.005)  # small steps improve here
    best = run(clip, dataclasses.replace(cfg, candidates=2, seed=3), checkpoints=False)
    singles = [run(clip, dataclasses.replace(cfg, seed=s), checkpoints=False) for s in (3, 4)]
    losses = [r.losses()["total"] for r in singles]
    assert losses[0] != losses[1]                         # the seeds' searches differ
    assert [c["seed"] for c in best.candidates] == [3, 4]
    assert [c["loss"] for c in best.candidates] == pytest.approx(losses)
    k = int(np.argmin(losses))
    assert [c["kept"] for c in best.candidates] == [k == 0, k == 1]
    np.testing.assert_array_equal(best.qpos, singles[k].qpos)
    assert best.config["candidates"] == 2 and singles[0].candidates == []


def test_tracking_start_is_a_second_start_guess(clip):
    res = run(clip, dataclasses.replace(TINY, tracking_start=True), checkpoints=False)
    plain = run(clip, TINY, checkpoints=False)
    for w, p in zip(res.windows, plain.windows):
        assert w["start"] in ("inverse_dynamics", "tracking")
        assert w["evaluations"] == p["evaluations"] + 1
    assert all(w["start"] == "inverse_dynamics" for w in plain.windows)


def test_balance_feedback_is_recorded_and_deterministic(clip):
    cfg = dataclasses.replace(TINY, balance=BalanceGains(frequency=1.0))
    res = run(clip, cfg, checkpoints=False)
    again = run(clip, cfg, checkpoints=False)
    plain = run(clip, TINY, checkpoints=False)
    np.testing.assert_array_equal(res.qpos, again.qpos)
    # The targets recorded are those applied, feedback included (rollout tests replay them).
    assert not np.array_equal(res.ctrl, plain.ctrl)
    # Switched off, the config (and so the checkpoint key) is what it was before the option.
    assert res.config["balance"]["frequency"] == 1.0 and "balance" not in plain.config


def _teleported(clip, frame: int):
    """The clip's estimate jumping 0.6 m forward at ``frame`` (no body can follow)."""
    body, fit, obs = clip
    jumped = fit.qpos.copy()
    jumped[frame:, 0] += 0.6
    cfg = dataclasses.replace(TINY, retries=0)
    res = optimize_dynamics(body, dataclasses.replace(fit, qpos=jumped), obs, cfg,
                            checkpoints=False, progress=False)
    return res, jumped, cfg


def test_a_window_left_far_from_the_estimate_hands_on_a_restart(clip):
    res, jumped, cfg = _teleported(clip, 5)
    resets = [i for i, w in enumerate(res.windows) if w["reset_after"]]
    assert resets and not res.windows[-1]["reset_after"]
    for i in resets:  # cut where the COM strayed, or restarted at the next window's start
        w, following = res.windows[i], res.windows[i + 1]
        assert w["cut_at"] == following["frames"][0] if w["cut_at"] is not None \
            else w["handover_error"] > cfg.reset_distance
    assert res.restarts == [res.windows[i + 1]["frames"][0] for i in resets]
    restart = res.restarts[-1]
    assert abs(res.qpos[restart, 0] - jumped[restart, 0]) < 0.05
    assert len(res.qpos) == len(jumped) and np.isfinite(res.qpos).all()


def test_a_last_window_that_strays_is_cut_and_restarted(clip):
    planned = run(clip, TINY, checkpoints=False).windows
    res, jumped, cfg = _teleported(clip, 15)  # inside the last planned window
    assert len(res.windows) == len(planned) + 1
    cut = res.windows[-2]["cut_at"]
    assert cut is not None and res.windows[-1]["frames"] == [cut, len(jumped) - 1]
    assert cut - res.windows[-2]["frames"][0] >= 5  # MIN_KEPT_SECONDS at 25 fps
    # After the restart the body is back near the estimate instead of left behind.
    assert abs(res.qpos[-1, 0] - jumped[-1, 0]) < 0.15
    assert len(res.ctrl) == len(run(clip, TINY, checkpoints=False).ctrl)


def test_a_body_left_below_a_rising_estimate_is_cut_where_its_head_falls_behind(clip):
    # The estimate rises 0.25 m off the floor (a get-up no standing body can follow); the
    # COM rule is put out of reach, so only the head's drop below the estimate's can cut.
    body, fit, obs = clip
    risen = fit.qpos.copy()
    risen[12:, 2] += 0.25
    risen_fit = dataclasses.replace(fit, qpos=risen)
    cfg = dataclasses.replace(TINY, retries=0, reset_distance=1.0, fall_distance=0.15)
    res = optimize_dynamics(body, risen_fit, obs, cfg, checkpoints=False, progress=False)
    cuts = [w["cut_at"] for w in res.windows if w["cut_at"] is not None]
    assert cuts and cuts[0] >= 12 and res.restarts[0] == cuts[0]
    assert abs(res.qpos[cuts[0], 2] - risen[cuts[0], 2]) < 0.05  # restarted on the estimate
    assert res.config["fall_distance"] == 0.15
    # Off (infinite, the default config), the COM alone decides: no cut, and the config, so
    # the checkpoint key, is what it was before the rule.
    off = optimize_dynamics(body, risen_fit, obs, dataclasses.replace(cfg, fall_distance=np.inf),
                            checkpoints=False, progress=False)
    assert not off.restarts and "fall_distance" not in off.config
    with pytest.raises(PhysposeError, match="fall_distance"):
        dataclasses.replace(cfg, fall_distance=0.0)


def test_a_continued_window_with_no_valid_sample_restarts_from_the_estimate(
        clip, tmp_path, monkeypatch):
    # The search of the second window, continued from the first one's simulated state, is
    # made to find no valid sample (a state handed over that was already heading for a
    # fall); the window must then be searched again from the kinematic state at its own
    # first frame, a recorded restart, rather than keep the least bad fall.
    search = optimize_module._search_with_retries
    calls = []

    def failing_when_continued(problem, simulator, setup, cfg, timing, w, *args):
        searched, best, initial, evaluations = search(problem, simulator, setup, cfg, timing,
                                                      w, *args)
        calls.append((w, problem.history is not None))
        if w == 1 and problem.history is not None:
            best = dataclasses.replace(best, valid=False, loss=np.inf)
        return searched, best, initial, evaluations

    monkeypatch.setattr(optimize_module, "_search_with_retries", failing_when_continued)
    res = run(clip, TINY, checkpoint_dir=tmp_path)
    assert calls[:3] == [(0, False), (1, True), (1, False)]
    first = res.windows[1]["frames"][0]
    assert res.windows[1]["restarted"] and res.windows[1]["valid"]
    assert res.windows[0]["reset_after"] and res.restarts[0] == first
    # The record keeps what the search from the state handed over tried, beside its own.
    continued = res.windows[1]["continued"]
    assert len(continued["attempt_log"]) >= 1 and "searched" in continued["attempt_log"][0]
    assert 0 < continued["evaluations"] < res.windows[1]["evaluations"]
    body, fit, obs = clip
    reference = reference_motion(body, fit, obs, TINY)
    np.testing.assert_allclose(res.qpos[first, 7:], reference[first, 7:], atol=1e-9)  # its pose
    assert np.linalg.norm(res.qpos[first, :3] - reference[first, :3]) < 0.02
    # Resumed from its checkpoints the run is the same, the restart read from the record.
    monkeypatch.setattr(optimize_module, "_search_with_retries", search)
    resumed = run(clip, TINY, checkpoint_dir=tmp_path)
    assert all(r.get("resumed") for r in resumed.windows)
    assert resumed.restarts == res.restarts
    np.testing.assert_array_equal(resumed.qpos, res.qpos)


def test_stretches_between_restarts_are_placed_on_the_estimate(clip, tmp_path):
    body, fit, obs = clip
    jumped = fit.qpos.copy()
    jumped[5:, 0] += 0.6
    moved_fit = dataclasses.replace(fit, qpos=jumped)
    cfg = dataclasses.replace(TINY, retries=0)
    placed = optimize_dynamics(body, moved_fit, obs, cfg, checkpoint_dir=tmp_path,
                               progress=False)
    bounds = [0, *placed.restarts, placed.num_frames]
    assert placed.restarts and placed.stretch_shifts.shape == (len(bounds) - 1, 2)
    # Placing happens after the windows: the same checkpoints serve both settings.
    raw = optimize_dynamics(body, moved_fit, obs,
                            dataclasses.replace(cfg, place_stretches=False),
                            checkpoint_dir=tmp_path, progress=False)
    assert len(list(tmp_path.iterdir())) == 1 and raw.stretch_shifts.shape == (0, 2)
    np.testing.assert_array_equal(raw.ctrl, placed.ctrl)
    for (a, b), d in zip(zip(bounds[:-1], bounds[1:]), placed.stretch_shifts):
        np.testing.assert_allclose(placed.qpos[a:b, :2] - raw.qpos[a:b, :2], np.tile(d, (b - a, 1)))
        np.testing.assert_allclose(placed.joints[a:b], raw.joints[a:b] + [*d, 0.0])
        np.testing.assert_array_equal(placed.qpos[a:b, 2:], raw.qpos[a:b, 2:])
        np.testing.assert_allclose(placed.cop[a:b], raw.cop[a:b] + [*d, 0.0])  # under the feet
    np.testing.assert_array_equal(placed.grf, raw.grf)


@pytest.mark.parametrize("independent", [False, True])
def test_interrupted_run_resumes_to_the_uninterrupted_result(clip, tmp_path, monkeypatch,
                                                             independent):
    cfg = dataclasses.replace(TINY, independent=independent, parallel_windows=1)
    whole = run(clip, cfg, checkpoint_dir=tmp_path / "a")
    save = checkpoint.save_window

    def save_then_stop(folder, index, arrays, record):
        path = save(folder, index, arrays, record)
        if index == 1:
            raise KeyboardInterrupt
        return path

    monkeypatch.setattr(checkpoint, "save_window", save_then_stop)
    with pytest.raises(KeyboardInterrupt):
        run(clip, cfg, checkpoint_dir=tmp_path / "b")
    monkeypatch.setattr(checkpoint, "save_window", save)
    folder = next((tmp_path / "b").iterdir())
    assert sorted(p.name for p in folder.iterdir()) == ["window_000.npz", "window_001.npz"]
    resumed = run(clip, cfg, checkpoint_dir=tmp_path / "b")
    np.testing.assert_array_equal(resumed.qpos, whole.qpos)
    np.testing.assert_array_equal(resumed.ctrl, whole.ctrl)
    # Its timings count this run's work only (they had added the earlier run's seconds).
    assert [bool(r.get("resumed")) for r in resumed.windows[:2]] == [True, True]
    assert resumed.timings["search"] == pytest.approx(
        sum(r["seconds"] for r in resumed.windows[2:]))
    for key in ("grf", "cop", "torques"):
        np.testing.assert_array_equal(getattr(resumed, key), getattr(whole, key))
    # A changed config never reuses these windows.
    run(clip, dataclasses.replace(cfg, seed=3), checkpoint_dir=tmp_path / "b")
    assert len(list((tmp_path / "b").iterdir())) == 2


def test_windows_checkpointed_without_forces_resume_with_nan_forces(clip, tmp_path):
    whole = run(clip, checkpoint_dir=tmp_path)
    folder = next(tmp_path.iterdir())
    first = checkpoint.load_window(folder, 0)
    arrays = {k: v for k, v in first[0].items() if not k.startswith("step_")}
    checkpoint.save_window(folder, 0, arrays, first[1])  # as an earlier physpose wrote it
    resumed = run(clip, checkpoint_dir=tmp_path)
    np.testing.assert_array_equal(resumed.qpos, whole.qpos)
    second = resumed.windows[1]["frames"][0]  # the frames before it are the first window's
    assert np.isnan(resumed.grf[:second]).all() and np.isnan(resumed.torques[:second]).all()
    assert np.isfinite(resumed.grf[second + 1:]).all()


def test_a_damaged_checkpoint_is_optimised_again(clip, tmp_path, caplog):
    """A window file cut short (a full disk, a partial copy) is dropped with a warning and
    that window is optimised again, to the result of the run that wrote it."""
    whole = run(clip, checkpoint_dir=tmp_path)
    folder = next(tmp_path.iterdir())
    damaged = checkpoint.window_path(folder, 1)
    damaged.write_bytes(damaged.read_bytes()[:200])
    with caplog.at_level("WARNING", logger="physpose.dynamics.checkpoint"):
        resumed = run(clip, checkpoint_dir=tmp_path)
    assert "unreadable checkpoint" in caplog.text and damaged.name in caplog.text
    np.testing.assert_array_equal(resumed.qpos, whole.qpos)
    assert checkpoint.load_window(folder, 1) is not None  # written again


def test_checkpoints_that_cannot_be_written_cost_only_the_resumption(clip, tmp_path, caplog):
    whole = run(clip, checkpoints=False)
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    with caplog.at_level("WARNING", logger="physpose.dynamics.checkpoint"):
        res = run(clip, checkpoint_dir=blocker)
    assert "cannot write this window's checkpoint" in caplog.text
    np.testing.assert_array_equal(res.qpos, whole.qpos)


def test_independent_windows_are_blended(clip):
    res = run(clip, dataclasses.replace(TINY, independent=True), checkpoints=False)
    assert np.isfinite(res.qpos).all() and np.isfinite(res.grf).all()
    assert len(res.ctrl) == int(round((len(res.qpos) - 1) / 25.0 / 0.005))
    np.testing.assert_allclose(np.linalg.norm(res.qpos[:, 3:7], axis=1), 1.0)
    wins = plan_windows(41, 25.0, 0.005, 0.4, 0.16, anchor_last=True)
    weights = blend_weights(wins, 41)
    np.testing.assert_allclose(weights.sum(axis=0), 1.0)
    assert wins[-1].last == 40 and wins[-1].last - wins[-1].first == 10


@pytest.mark.parametrize("frames, fps, overlap", [(100, 30.0, 0.6), (110, 60.0, 0.2), (41, 25.0, 0.16)])
def test_independent_windows_fade_linearly_into_what_came_before(frames, fps, overlap):
    # Each window fades in linearly over its overlap with all the windows before it, also
    # where the anchored last window reaches over two of them, and the weights sum to 1.
    wins = plan_windows(frames, fps, 0.005, 1.0 if overlap > 0.16 else 0.4, overlap,
                        anchor_last=True)
    weights = blend_weights(wins, frames)
    np.testing.assert_allclose(weights.sum(axis=0), 1.0)
    assert (weights >= 0).all()
    last = wins[-1]
    fade = weights[-1, last.first:max(w.last for w in wins[:-1]) + 1]
    assert len(fade) > 1 and (fade < 1).all()
    np.testing.assert_allclose(np.diff(fade), fade[0], atol=1e-12)
    assert (weights[0, :wins[1].first] == 1).all()


@pytest.mark.parametrize("fps", [24.0, 25.0, 29.97, 30.0, 60.0])
def test_every_sequential_window_has_coefficients_of_its_own(fps):
    # A window that begins and ends between two knots would have no spline coefficient that
    # begins inside it, and CMA-ES cannot search nothing: a short last window (small
    # overlaps, some clip lengths) is merged into the one before it.
    dt, knots = 0.005, 0.1
    for window, overlap in ((1.0, 0.0), (1.0, 0.05), (0.24, 0.0), (1.0, 0.6)):
        for frames in range(3, 200):
            wins = plan_windows(frames, fps, dt, window, overlap, min_span=knots)
            assert wins[0].first == 0 and wins[-1].last == frames - 1
            assert all(b.first <= a.last for a, b in zip(wins, wins[1:]))
            grid = KnotGrid(knots, wins[-1].end_step * dt)
            for win in wins[1:]:
                free = grid.searched(win.start_step * dt, win.end_step * dt, continued=True)
                assert free.start < free.stop, (frames, win)


@pytest.mark.parametrize("fps", [25.0, 30.0])
def test_independent_windows_cover_every_frame_whatever_the_overlap(fps):
    # The anchored last window keeps the full length; merging a short last window into the
    # one before it as well once left frames that no window covered (63 frames at 30 fps in
    # 1 s windows without overlap: 31), whose joined motion was then 0 / 0.
    for window, overlap in ((1.0, 0.0), (1.0, 0.05), (0.24, 0.0), (1.0, 0.6)):
        for frames in range(3, 200):
            wins = plan_windows(frames, fps, 0.005, window, overlap, anchor_last=True,
                                min_span=0.5)
            assert wins[0].first == 0 and wins[-1].last == frames - 1
            assert all(b.first <= a.last for a, b in zip(wins, wins[1:])), (frames, wins)
            np.testing.assert_allclose(blend_weights(wins, frames).sum(axis=0), 1.0)


def test_a_short_last_window_is_searched_with_the_one_before(clip):
    # 21 frames in windows of 6 without overlap would leave frames 18-20 (0.72-0.80 s)
    # between two knots; they join the window before.
    res = run(clip, dataclasses.replace(TINY, window=0.24, overlap=0.0), checkpoints=False)
    assert [w["frames"] for w in res.windows] == [[0, 6], [6, 12], [12, 20]]
    assert np.isfinite(res.qpos).all()


def test_mismatched_inputs_are_refused(clip):
    body, fit, obs = clip
    with pytest.raises(PhysposeError, match="observed frames"):
        optimize_dynamics(body, fit, obs.replace(keypoints2d=obs.keypoints2d[:-1],
                                                 timestamps=obs.timestamps[:-1],
                                                 detected=obs.detected[:-1],
                                                 interpolated=obs.interpolated[:-1],
                                                 world_landmarks=obs.world_landmarks[:-1]),
                          TINY, checkpoints=False, progress=False)
    bad = dataclasses.replace(fit, qpos=np.where(np.arange(55) == 9, np.nan, fit.qpos))
    with pytest.raises(PhysposeError, match="not finite"):
        optimize_dynamics(body, bad, obs, TINY, checkpoints=False, progress=False)


def test_search_sets():
    """Which hinges each search set varies: legs only, legs and trunk, or all 48."""
    names = {DOF_NAMES[k].split("_")[1] for k in searched_dofs("legs")}
    assert names == {"hip", "knee", "ankle"} and len(searched_dofs("legs")) == 18
    trunk = {DOF_NAMES[k].split("_")[0] for k in searched_dofs("legs_trunk")}
    assert len(searched_dofs("legs_trunk")) == 24 and {"spine", "thorax"} <= trunk
    assert len(searched_dofs("all")) == 48
    with pytest.raises(PhysposeError, match="search"):
        DynamicsConfig(search="arms")


def test_averaged_searches_keep_the_average_unless_it_is_worse_than_every_search(clip):
    cfg = dataclasses.replace(TINY, popsize=6, iterations=3)
    res = run(clip, dataclasses.replace(cfg, searches=3), checkpoints=False)
    single = run(clip, cfg, checkpoints=False)
    per_search = 1 + cfg.iterations * (cfg.popsize + 1)
    kept = []
    for w in res.windows:
        assert len(w["search_losses"]) == 3
        if w["kept"] == "average":   # three searches from one start, plus the average's rollout
            assert w["evaluations"] == 3 * per_search + 1
            assert w["loss_final"] <= max(w["search_losses"])
        else:                        # the average was worse than every search: the best is kept
            assert w["loss_final"] == min(w["search_losses"])
            assert w["kept"] == f"search {int(np.argmin(w['search_losses']))}"
        kept.append(w["kept"])
    assert "average" in kept
    # One search is the former behaviour (the first side-by-side search keeps the seed), and
    # leaves the checkpoint key as it was.
    assert single.windows[0]["search_losses"] == [single.windows[0]["loss_final"]]
    assert res.windows[0]["search_losses"][0] == pytest.approx(single.windows[0]["loss_final"])
    assert "searches" not in cfg.identity() and res.config["searches"] == 3
    with pytest.raises(PhysposeError, match="searches"):
        DynamicsConfig(searches=0)


def test_refinement_is_recorded_and_brings_the_body_nearer_the_estimate(clip):
    """iLQR after each window's search (and instead of it): every window records the
    refinement, the tracking cost falls, and the motion ends nearer the estimate's joints."""
    from physpose.dynamics.ilqr import RefineConfig  # noqa: PLC0415

    body, fit, _ = clip
    plain = run(clip, dataclasses.replace(TINY, iterations=0), checkpoints=False)
    refined = run(clip, dataclasses.replace(TINY, iterations=0,
                                            refine=RefineConfig(iterations=2)), checkpoints=False)
    for w in refined.windows:
        assert w["refine"]["cost_final"] < w["refine"]["cost_initial"]
        assert w["refine"]["kept"] and w["valid"]
    assert "refine" not in plain.windows[0]

    def error(res) -> float:
        return float(np.linalg.norm(res.joints - fit.joints, axis=-1).mean())

    assert error(refined) < error(plain)
    # A window keeps the refined targets only when their objective is at most keep_ratio
    # times the search's: at 0 none does, and the result is the search's.
    refused = run(clip, dataclasses.replace(TINY, iterations=0, refine=RefineConfig(
        iterations=2, keep_ratio=0.0)), checkpoints=False)
    assert not any(w["refine"]["kept"] for w in refused.windows)
    np.testing.assert_array_equal(refused.joints, plain.joints)
    both = run(clip, dataclasses.replace(TINY, independent=True,
                                         refine=RefineConfig(iterations=1)), checkpoints=False)
    assert all("refine" in w for w in both.windows)


def _displaced_by_60cm(clip, **config):
    """Optimise the clip whose estimate jumps 0.6 m sideways after frame 5 (which no window
    can follow), one retry and one refinement iteration per window, ``config`` on top."""
    body, fit, obs = clip
    jumped = fit.qpos.copy()
    jumped[5:, 0] += 0.6
    cfg = dataclasses.replace(TINY, retries=1, refine=RefineConfig(iterations=1), **config)
    return optimize_dynamics(body, dataclasses.replace(fit, qpos=jumped), obs, cfg,
                             checkpoints=False, progress=False)


@pytest.mark.parametrize("refine_within", [np.inf, 1e-3])
def test_each_attempt_is_logged(clip, refine_within):
    """A window that cannot follow the estimate is retried; every attempt's handover error,
    after its search and after its refinement, and its time are in the window's record. An
    attempt that hands on from further than refine_within is refined only if it is kept."""
    res = _displaced_by_60cm(clip, refine_within=refine_within)
    retried = [w for w in res.windows if w["attempts"] == 2]
    assert retried
    for w in res.windows:
        log = w["attempt_log"]
        assert len(log) == w["attempts"] and all(a["seconds"] > 0 for a in log)
        refined = [a for a in log if "refined" in a]
        assert all(set(a) == {"searched", "refined", "seconds", "refine_seconds"}
                   for a in refined)
        errors = [np.inf if a["refined"] is None else a["refined"] for a in refined]
        if refine_within == np.inf:
            assert refined == log and w["handover_error"] == min(errors)
        else:  # no attempt comes within 1 mm: only the kept one is refined, retried or not
            assert len(refined) == 1 and w["handover_error"] == errors[0]


def test_a_window_missing_by_more_than_retry_within_is_not_retried(clip):
    """The displaced estimate of the test above, whose windows were retried: with
    retry_within 1 mm no window is, and each keeps (and refines) its one attempt."""
    res = _displaced_by_60cm(clip, retry_within=1e-3)
    for w in res.windows:
        assert w["attempts"] == 1 and len(w["attempt_log"]) == 1
        assert "refined" in w["attempt_log"][0]


def test_a_start_takes_the_depth_speed_of_the_estimate_low_passed(clip):
    """An estimate whose root shakes along the camera's line of sight (3 Hz, 2 cm, its speed
    largest at the start): started with that speed, the simulated body moves off in depth
    (1.6 cm in 0.12 s); started with it low-passed, it stays near its place (under 1 mm)."""
    body, fit, obs = clip
    rot, shift = fit.T_world2cam[:3, :3], fit.T_world2cam[:3, 3]
    sight = fit.qpos[0, :2] - (-rot.T @ shift)[:2]
    sight /= np.linalg.norm(sight)
    t = np.arange(fit.num_frames) / fit.fps
    shaken = fit.qpos.copy()
    shaken[:, :2] += 0.02 * np.sin(2 * np.pi * 3.0 * t)[:, None] * sight
    shaken_clip = (body, dataclasses.replace(fit, qpos=shaken), obs)
    cfg = dataclasses.replace(TINY, iterations=0)  # the start targets as they are: no search
    lurch = {}
    for sigma in (0.0, 0.25):
        res = run(shaken_clip, dataclasses.replace(cfg, start_sight_smoothing=sigma),
                  checkpoints=False)
        lurch[sigma] = abs((res.qpos[3, :2] - res.qpos[0, :2]) @ sight)
    assert lurch[0.0] > 0.01 and lurch[0.25] < 0.3 * lurch[0.0]


@pytest.mark.parametrize("fps", [30.0, 60.0])
def test_the_com_velocity_target_is_taken_at_the_frame_times(fps):
    # At 30 or 60 fps the frames fall between the 5 ms simulation steps; the target velocity
    # is taken frame to frame, so a frame moved onto its nearest step would make a body
    # gliding at a constant speed speed up and slow down by 10-20 % every three frames.
    body = build_body(BodyShape.from_height(1.7))
    fit, obs, _ = simulated_clip(body, "stand", seconds=0.8, fps=fps)
    t = np.arange(fit.num_frames) / fps
    qpos = fit.qpos.copy()
    qpos[:, 0] += 0.8 * t                       # the whole body glides at 0.8 m/s
    fit = dataclasses.replace(fit, qpos=qpos)
    cfg = dataclasses.replace(TINY, flat_stance=False, ground_reference=False)
    setup = optimize_module._setup(optimize_module.sim_model(body), fit, obs, cfg)
    speed = setup.objective.com_velocity[3:-3, 0]  # away from the clip's padded ends
    assert np.abs(speed - 0.8).max() < 0.02
    ref = reference_motion(body, fit, obs, cfg)
    assert np.abs(np.diff(ref[3:-3, 0]) * fps - 0.8).max() < 0.02
