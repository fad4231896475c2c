"""The HTML report without a browser: one self-contained file with the data the viewer needs."""

from __future__ import annotations

import json
import re

import pytest

import physpose.report as report
from physpose.errors import PhysposeError
from physpose.reconstruction import Reconstruction
from physpose.report import build_report
from physpose.report.data import (forces_summary, grf_plot, report_data, summary_rows,
                                  window_losses)
from synthetic_result import make_reconstruction, save_result

needs_bundle = pytest.mark.skipif(not report.BUNDLE.is_file(),
                                  reason="viewer bundle not built; run `make setup` (make web)")


def _data(page: str) -> dict:
    m = re.search(r'<script type="application/json" id="physpose-data">(.*?)</script>', page, re.S)
    assert m, "data block missing"
    return json.loads(m.group(1))


@needs_bundle
def test_report_is_self_contained_and_carries_both_motions(tmp_path):
    folder = save_result(tmp_path, num_frames=20)
    path = build_report(folder)
    assert path == folder / "report.html"
    page = path.read_text()
    assert "three.js" not in re.findall(r'src="([^"]+)"', page)
    assert not re.search(r'<(script|link)[^>]+(src|href)="(https?:)?//', page), "external asset"
    # Exactly one data block and one inline script; the bundle never closes the script early.
    assert page.count("<script") == 2 and page.count("</script>") == 2
    data = _data(page)
    assert data["frames"] == 20 and data["default_motion"] == "physics"
    assert set(data["motions"]) == {"kinematic", "physics"}
    phys = data["motions"]["physics"]
    assert len(phys["joints"]) == 20 * 21 * 3
    assert len(phys["body_pos"]) == 20 * len(data["body"]["names"]) * 3
    assert len(phys["contacts"]) == 20 * 2 and len(phys["feet_xy"]) == 40
    assert {p["id"] for p in data["plots"]} == {"feet", "com", "gap", "grf", "losses"}
    for element in ('id="view"', 'id="play"', 'id="scrub"', 'id="frame"', 'value="kinematic"'):
        assert element in page
    assert "mpjpe_g_mm" in page and "41.5" in page


@needs_bundle
def test_kinematic_only_result_without_body_draws_a_skeleton(tmp_path):
    folder = save_result(tmp_path, num_frames=8, physics=False, qpos_kinematic=False, meta={})
    data = _data(build_report(folder, tmp_path / "r" / "k.html").read_text())
    assert list(data["motions"]) == ["kinematic"] and data["body"] is None
    assert data["motions"]["kinematic"]["body_pos"] is None
    assert len(data["edges"]) == 22
    # Plots of what is present only: no physics gap, no centre of mass, no losses.
    assert [p["id"] for p in data["plots"]] == ["feet"]


@needs_bundle
def test_a_result_with_positions_that_are_not_numbers_is_an_error(tmp_path):
    folder = save_result(tmp_path, num_frames=6, physics=False, qpos_kinematic=False, meta={})
    rec = Reconstruction.load(folder)
    joints = rec.joints_kinematic.copy()
    joints[3, 2] = float("nan")
    rec.replace(joints_kinematic=joints).save(folder / "reconstruction.npz")
    with pytest.raises(PhysposeError, match="positions that are not numbers") as caught:
        build_report(folder)
    assert caught.value.path == str(folder / "reconstruction.npz")


@needs_bundle
def test_metrics_argument_with_groups_becomes_columns(tmp_path):
    folder = save_result(tmp_path, num_frames=4)
    metrics = {"kinematic": {"mpjpe_mm": 80.0}, "physics": {"mpjpe_mm": 70.5, "skate_pct": 1.0}}
    page = build_report(folder, metrics=metrics).read_text()
    assert "<th>kinematic</th><th>physics</th>" in page
    assert '<td>skate_pct</td><td>—</td><td class="num">1</td>' in page


def test_window_losses_plot_what_is_present():
    windows = [{"start": 0.0, "terms": {"com": 2.0, "pose": float("nan")}},
               {"start": 0.5, "losses": {"com": 1.0, "2d": 500.0}}]
    spec = window_losses({"dynamics": {"windows": windows}})
    assert [s["name"] for s in spec["series"]] == ["2d", "com"]
    assert spec["series"][0]["y"] == [None, 500.0] and spec["x"] == [0.0, 0.5]
    assert spec["log_y"] is True
    assert window_losses({}) is None and window_losses({"dynamics": {"windows": [{}]}}) is None


def test_missing_bundle_tells_the_user_to_run_setup(tmp_path, monkeypatch):
    monkeypatch.setattr(report, "BUNDLE", tmp_path / "absent.js")
    with pytest.raises(PhysposeError, match="make setup"):
        build_report(save_result(tmp_path, num_frames=3))


def test_window_losses_read_the_dynamics_stage_windows():
    """The dynamics stage writes terms_final, frames and a non-numeric 'start' (its init)."""
    windows = [{"frames": [0, 25], "start": "inverse_dynamics", "terms_final": {"com": 0.2}},
               {"frames": [15, 40], "start": "handover", "terms_final": {"com": 0.1}}]
    spec = window_losses({"dynamics": {"windows": windows}}, fps=25.0)
    assert spec["x"] == [0.0, 0.6] and spec["xlabel"] == "window start (s)"
    assert spec["series"][0]["y"] == [0.2, 0.1]
    no_fps = window_losses({"dynamics": {"windows": windows}})
    assert no_fps["x"] == [0.0, 1.0] and no_fps["xlabel"] == "window"


def test_ground_reaction_force_plot_in_body_weights_with_gaps():
    import mujoco
    import numpy as np

    rec = make_reconstruction(num_frames=20)
    weight = mujoco.MjModel.from_xml_string(rec.body_mjcf).body_subtreemass[0] * 9.81
    grf = rec.grf_physics.copy()
    grf[5:8] = np.nan  # windows resumed from checkpoints that hold no forces
    plot = grf_plot(rec.replace(grf_physics=grf))
    assert plot["ylabel"] == "body weights" and plot["cursor"]
    left, right = plot["series"]  # the rest of the body touches nothing: no third line
    assert left["name"] == "left foot" and right["name"] == "right foot"
    assert left["y"][5:8] == [None, None, None]
    assert left["y"][0] == pytest.approx(rec.grf_physics[0, 0, 2] / weight, abs=1e-4)
    assert left["y"][0] + right["y"][0] == pytest.approx(1.0, abs=1e-3)
    json.dumps(plot, allow_nan=False)  # the page's JSON holds no NaN
    assert grf_plot(rec.replace(body_mjcf=None))["ylabel"] == "N"
    assert grf_plot(rec.replace(grf_physics=np.full_like(grf, np.nan))) is None
    assert grf_plot(make_reconstruction(num_frames=5, physics=False)) is None


def test_forces_summary_gives_the_peak_loads_and_the_joints_at_their_limits(tmp_path):
    import numpy as np

    from physpose.body import build_body
    from physpose.shape import BodyShape
    from physpose.skeleton import DOF_NAMES

    body = build_body(BodyShape.from_height(1.7))
    weight = body.total_mass * 9.81
    rec = make_reconstruction(num_frames=10).replace(body_mjcf=body.xml)
    grf = np.zeros((10, 3, 3))
    grf[:, 0, 2], grf[4, 1, 2] = 0.5 * weight, 1.5 * weight
    torques = np.zeros((10, 48))
    knee = DOF_NAMES.index("r_knee_y")
    torques[[2, 3], knee] = -body.torque_limit[knee]
    line = forces_summary(rec.replace(grf_physics=grf, torques_physics=torques))
    assert line.startswith("peak vertical ground reaction force 0.50 (left foot) and 1.50 "
                           "(right foot) body weights")
    assert line.endswith("a joint at its servo's torque limit in 20 % of frames (most often "
                         "r_knee_y)")
    calm = forces_summary(rec.replace(grf_physics=grf, torques_physics=0.5 * torques))
    assert calm.endswith("no joint at its servo's torque limit")
    assert dict(summary_rows(rec.replace(grf_physics=grf, torques_physics=torques),
                             tmp_path))["physics forces"] == line
    assert forces_summary(rec.replace(grf_physics=np.full_like(grf, np.nan))) is None
    assert "physics forces" not in dict(summary_rows(rec.replace(grf_physics=None), tmp_path))


def test_restarts_are_marked_on_the_gap_plot_and_in_the_summary(tmp_path):
    rec = make_reconstruction(num_frames=12, meta={"dynamics": {"windows": [], "restarts": [4, 9]}})
    gap = next(p for p in report_data(rec)["plots"] if p["id"] == "gap")
    (band,) = gap["bands"]
    assert [i for i, on in enumerate(band["on"]) if on] == [4, 9] and "restart" in band["name"]
    rows = dict(summary_rows(rec, tmp_path))
    restarts = rows["physics restarts"]
    assert restarts.startswith("2,") and "0.16 s, 0.36 s" in restarts
    calm = rec.replace(meta={"dynamics": {"restarts": []}})
    assert dict(summary_rows(calm, tmp_path))["physics restarts"].startswith("none")
    kinematic = rec.replace(joints_physics=None, landmarks_physics=None, qpos_physics=None)
    assert "physics restarts" not in dict(summary_rows(kinematic, tmp_path))


def test_slow_motion_footage_is_named_in_the_summary(tmp_path):
    rec = make_reconstruction(num_frames=12)
    assert "slow motion" not in dict(summary_rows(rec, tmp_path))
    slowed = rec.replace(fps=4 * rec.fps, meta={**rec.meta, "slow_motion": 4.0})
    rows = dict(summary_rows(slowed, tmp_path))
    assert rows["slow motion"].startswith("the footage plays 4x slower than real time")
    assert rows["frame rate"] == f"{4 * rec.fps:g} Hz"


@needs_bundle
def test_frames_without_a_detection_are_marked_and_listed(tmp_path):
    rec = make_reconstruction(num_frames=12)
    kp = rec.keypoints2d.copy()
    kp[3:7] = 0  # a gap too long to interpolate: every confidence 0
    rec = rec.replace(keypoints2d=kp)
    gap = next(p for p in report_data(rec)["plots"] if p["id"] == "gap")
    band = next(b for b in gap["bands"] if b["name"] == "no person detected")
    assert [i for i, on in enumerate(band["on"]) if on] == [3, 4, 5, 6]
    row = dict(summary_rows(rec, tmp_path))["frames without a detection"]
    assert row.startswith("4,") and "0.12-0.28 s" in row
    assert "frames without a detection" not in dict(summary_rows(make_reconstruction(12),
                                                                 tmp_path))


def test_input_warnings_are_listed_in_the_summary(tmp_path):
    rec = make_reconstruction(num_frames=12, meta={"diagnostics": {
        "person_jumps": [5], "raised": [], "supports": [], "invalid_windows": [[2, 8]]}})
    warnings = [v for k, v in summary_rows(rec, tmp_path) if k == "warning"]
    assert len(warnings) == 2
    assert "jumps further than a body moves" in warnings[0] and "--start/--end" in warnings[0]
    assert "no simulated motion stayed valid" in warnings[1]
    assert all(k != "warning" for k, _ in summary_rows(make_reconstruction(12), tmp_path))


def test_the_summary_says_where_the_result_lies_in_its_video(tmp_path):
    rec = make_reconstruction(num_frames=3, meta={"source": "walk.mp4",
                                                  "frame_indices": [60, 61, 62],
                                                  "timestamps": [1.0, 1.02, 1.04],
                                                  "slow_motion": 2.0})
    rows = summary_rows(rec, tmp_path)
    assert rows[1] == ("video", "walk.mp4")
    assert rows[2] == ("in the video", "2.00-2.08 s (frames 60-62)")  # footage seconds
    assert "in the video" not in dict(summary_rows(make_reconstruction(num_frames=3), tmp_path))


@needs_bundle
def test_stored_metrics_are_shown_under_their_labels_and_undefined_ones_as_a_dash(tmp_path):
    """`physpose report` on a folder reads the metrics write_outputs stored, and shows them as
    the summary does; a metric a short clip leaves undefined (NaN) is a dash, not 'nan'."""
    meta = {"metrics": {"kinematic": {"foot_skate_pct": 2.5, "jitter_mps2": float("nan")}}}
    folder = save_result(tmp_path, num_frames=4, meta=meta)
    page = build_report(folder).read_text()
    assert "<td>foot skate (% frames)</td><td class=\"num\">2.5</td>" in page
    assert "<td>jitter (m/s^2)</td><td>—</td>" in page
    assert "foot_skate_pct</td>" not in page and ">nan<" not in page
