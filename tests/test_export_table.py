"""CSV and JSON joint tables hold every joint of every motion at the analysis frames."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from physpose.errors import PhysposeError
from physpose.export import export
from physpose.export.gltf import read_glb
from physpose.export.table import CSV_COLUMNS, forces_columns
from physpose.reconstruction import Reconstruction
from physpose.skeleton import DOF_NAMES
from synthetic_result import save_result


def _read_csv(path, joint_names):
    with path.open() as f:
        rows = list(csv.DictReader(f))
    out = {}
    for r in rows:
        arr = out.setdefault(r["motion"], {})
        arr[(int(r["frame"]), joint_names.index(r["joint"]))] = (
            float(r["x"]), float(r["y"]), float(r["z"]), float(r["time"]))
    return rows, out


def test_csv_round_trip_both_motions(tmp_path):
    folder = save_result(tmp_path, num_frames=7)
    rec = Reconstruction.load(folder)
    path = export(folder, "csv")
    assert path == folder / "joints.csv"
    assert path.read_text().splitlines()[0] == ",".join(CSV_COLUMNS)
    rows, table = _read_csv(path, rec.joint_names)
    assert len(rows) == 2 * 7 * len(rec.joint_names)
    for motion, joints in (("kinematic", rec.joints_kinematic), ("physics", rec.joints_physics)):
        back = np.array([[table[motion][(t, j)][:3] for j in range(len(rec.joint_names))]
                         for t in range(7)])
        assert np.abs(back - joints).max() < 1e-6
    assert table["physics"][(5, 0)][3] == pytest.approx(5 / rec.fps)


def test_json_round_trip_and_motion_choice(tmp_path):
    folder = save_result(tmp_path, num_frames=5)
    rec = Reconstruction.load(folder)
    doc = json.loads(export(folder, "json", out=tmp_path / "x" / "j.json").read_text())
    assert doc["joint_names"] == list(rec.joint_names) and doc["fps"] == rec.fps
    assert np.abs(np.array(doc["motions"]["kinematic"]) - rec.joints_kinematic).max() < 1e-6
    assert np.abs(np.array(doc["motions"]["physics"]) - rec.joints_physics).max() < 1e-6
    only = json.loads(export(folder, "json", motion="kinematic").read_text())
    assert list(only["motions"]) == ["kinematic"]


def test_json_writes_a_missing_coordinate_as_null(tmp_path):
    """JSON has no NaN: a coordinate that is not a number is written as null, which strict
    parsers (a browser's JSON.parse) accept, where Python's bare NaN token is refused."""
    folder = save_result(tmp_path, num_frames=4)
    rec = Reconstruction.load(folder)
    joints = rec.joints_kinematic.copy()
    joints[2, 3] = np.nan
    rec.replace(joints_kinematic=joints).save(folder / "reconstruction.npz")

    def refuse(token):
        raise ValueError(f"non-standard JSON token {token}")
    doc = json.loads(export(folder, "json", motion="kinematic").read_text(),
                     parse_constant=refuse)
    assert doc["motions"]["kinematic"][2][3] == [None, None, None]
    assert doc["motions"]["kinematic"][2][2] == pytest.approx(joints[2, 2].tolist(), abs=1e-6)
    # The CSV leaves the cells empty, as forces.csv does (it had written the text "nan").
    with export(folder, "csv", motion="kinematic").open() as f:
        row = [r for r in csv.DictReader(f) if r["frame"] == "2"][3]
    assert (row["x"], row["y"], row["z"]) == ("", "", "")


def test_kinematic_only_result_exports_kinematic_rows(tmp_path):
    folder = save_result(tmp_path, num_frames=3, physics=False, qpos_kinematic=False)
    rows, _ = _read_csv(export(folder, "csv"), Reconstruction.load(folder).joint_names)
    assert {r["motion"] for r in rows} == {"kinematic"}
    with pytest.raises(PhysposeError, match="no physics motion"):
        export(folder, "csv", motion="physics")


def test_forces_table_round_trip(tmp_path):
    folder = save_result(tmp_path, num_frames=20)
    rec = Reconstruction.load(folder)
    path = export(folder, "forces")
    assert path == folder / "forces.csv"
    with path.open() as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == forces_columns() and len(rows) == 20
    assert len(forces_columns()) == 2 + 9 + 6 + 48 + 2 + 3
    fz = np.array([[float(r["l_foot_fz_n"]), float(r["r_foot_fz_n"])] for r in rows])
    assert np.abs(fz - rec.grf_physics[:, :2, 2]).max() < 1e-6
    torque = np.array([float(r["r_knee_y_torque_nm"]) for r in rows])
    assert np.abs(torque - rec.torques_physics[:, DOF_NAMES.index("r_knee_y")]).max() < 1e-6
    # A foot in the air has no centre of pressure: empty cells, not a made-up point.
    airborne = np.isnan(rec.cop_physics[:, 0, 0])
    assert airborne.any() and all((r["l_cop_x_m"] == "") == a for r, a in zip(rows, airborne))
    assert float(rows[3]["time"]) == pytest.approx(3 / rec.fps)


def test_tables_say_where_each_frame_is_in_the_video(tmp_path):
    """A result of --start 2 (or with unseen first frames left out) begins some way into the
    video: the tables carry each frame's place there, in seconds of the footage (slow motion
    included) and in the video's own frames; a result without them leaves the cells empty."""
    folder = save_result(tmp_path / "old", num_frames=5)
    rec = Reconstruction.load(folder / "reconstruction.npz")
    assert rec.video_times is None and rec.video_frames is None
    with export(folder, "csv").open() as f:
        rows = list(csv.DictReader(f))
    assert rows[0]["video_time"] == rows[0]["video_frame"] == ""
    assert json.loads(export(folder, "json").read_text())["video_times"] is None
    timed = rec.replace(meta={**rec.meta, "slow_motion": 2.0, "frame_indices": [60, 62, 65, 67, 70],
                              "timestamps": [1.0, 1.04, 1.08, 1.12, 1.16]})
    later = tmp_path / "later"
    later.mkdir()
    timed.save(later / "reconstruction.npz")
    with export(later, "csv").open() as f:
        rows = [r for r in csv.DictReader(f) if r["joint"] == rec.joint_names[0]]
    rows = rows[:5]  # the first motion's
    assert [float(r["video_time"]) for r in rows] == pytest.approx([2.0, 2.08, 2.16, 2.24, 2.32])
    assert [int(r["video_frame"]) for r in rows] == [60, 62, 65, 67, 70]
    assert float(rows[1]["time"]) == pytest.approx(1 / rec.fps)  # still from the first frame
    doc = json.loads(export(later, "json").read_text())
    assert doc["video_frames"] == [60, 62, 65, 67, 70] and doc["video_times"][-1] == 2.32
    with export(later, "forces").open() as f:
        rows = list(csv.DictReader(f))
    assert rows[4]["video_frame"] == "70" and float(rows[4]["video_time"]) == pytest.approx(2.32)


def test_tables_mark_the_frames_not_to_trust(tmp_path):
    """Undetected frames (inferred from their neighbours), the physics' restarts (it jumps
    there) and its windows without a valid sample are marked per frame in every table: the
    npz and the summary had said so, the exports had not."""
    rec = Reconstruction.load(save_result(tmp_path / "base", num_frames=8) / "reconstruction.npz")
    kp = rec.keypoints2d.copy()
    kp[2:4, :, 2] = 0.0  # no detection in frames 2-3
    marked = rec.replace(keypoints2d=kp, meta={
        **rec.meta, "dynamics": {**(rec.meta.get("dynamics") or {}), "restarts": [5]},
        "diagnostics": {"invalid_windows": [[6, 7]]}})
    # Results before stop 75 say nothing else: the frames with confidences count as detected.
    assert marked.detected.tolist() == [True, True, False, False, True, True, True, True]
    # Frame 1 filled across a short gap at observe time: confidences, but not detected.
    marked = marked.replace(meta={**marked.meta, "detected": [True, False, False, False,
                                                               True, True, True, True]})
    folder = tmp_path / "marked"
    folder.mkdir()
    marked.save(folder / "reconstruction.npz")
    with export(folder, "csv").open() as f:
        rows = [r for r in csv.DictReader(f) if r["joint"] == rec.joint_names[0]]
    by_motion = {m: [r for r in rows if r["motion"] == m] for m in ("kinematic", "physics")}
    for motion_rows in by_motion.values():
        assert [r["detected"] for r in motion_rows] == list("10001111")
    assert [r["physics_restart"] for r in by_motion["physics"]] == list("00000100")
    assert [r["physics_invalid"] for r in by_motion["physics"]] == list("00000011")
    assert {r["physics_restart"] for r in by_motion["kinematic"]} == {""}
    doc = json.loads(export(folder, "json").read_text())
    assert doc["detected"] == [True, False, False, False, True, True, True, True]
    assert doc["physics_restart"] == [f == 5 for f in range(8)]
    assert doc["physics_invalid"] == [f >= 6 for f in range(8)]
    with export(folder, "forces").open() as f:
        rows = list(csv.DictReader(f))
    assert [r["physics_restart"] for r in rows] == list("00000100")
    assert [r["detected"] for r in rows] == list("10001111")
    # glTF keeps them in its animation's extras (BVH has no place for them).
    doc, _ = read_glb(export(folder, "glb"))
    assert doc["animations"][0]["extras"] == {
        "detected": [True, False, False, False, True, True, True, True],
        "physics_restart": [f == 5 for f in range(8)],
        "physics_invalid": [f >= 6 for f in range(8)]}
    doc, _ = read_glb(export(folder, "glb", out=tmp_path / "k.glb", motion="kinematic"))
    assert doc["animations"][0]["extras"]["physics_restart"] is None
    kinematic = json.loads(export(save_result(tmp_path / "kin", num_frames=3, physics=False),
                                  "json").read_text())
    assert kinematic["detected"] == [True] * 3 and kinematic["physics_restart"] is None
    # A physics result that does not record its invalid windows leaves the cells empty.
    unknown = marked.replace(meta={**marked.meta, "diagnostics": {}})
    (tmp_path / "unknown").mkdir()
    unknown.save(tmp_path / "unknown" / "reconstruction.npz")
    with export(tmp_path / "unknown", "forces").open() as f:
        assert {r["physics_invalid"] for r in csv.DictReader(f)} == {""}


def test_forces_need_a_physics_result(tmp_path):
    folder = save_result(tmp_path, num_frames=3, physics=False)
    with pytest.raises(PhysposeError, match="no simulated forces"):
        export(folder, "forces")
    with pytest.raises(PhysposeError, match="only the physics motion"):
        export(save_result(tmp_path / "p", num_frames=3), "forces", motion="kinematic")


@pytest.mark.parametrize("problem", ["missing", "empty", "format"])
def test_bad_input_is_a_clear_error(tmp_path, problem):
    folder = save_result(tmp_path, num_frames=3)
    if problem == "missing":
        with pytest.raises(PhysposeError, match="result folder not found"):
            export(tmp_path / "nope", "csv")
    elif problem == "empty":
        (tmp_path / "empty").mkdir()
        with pytest.raises(PhysposeError, match="no reconstruction.npz"):
            export(tmp_path / "empty", "csv")
    else:
        with pytest.raises(PhysposeError, match="unknown export format 'fbx'"):
            export(folder, "fbx")


@pytest.mark.parametrize("fmt", ["csv", "bvh"])
def test_a_failed_write_keeps_the_earlier_file_and_leaves_no_part(tmp_path, monkeypatch, fmt):
    """A write that fails midway (a full disk) leaves no half file that looks complete, and
    the earlier export stays as it was."""
    import physpose.export as export_module

    folder = save_result(tmp_path, num_frames=4)
    out = export(folder, fmt)
    before = out.read_bytes()
    writer = {"csv": "write_csv", "bvh": "write_bvh"}[fmt]

    def full_disk(*args):
        Path(args[-1]).write_text("half a file")
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(export_module, writer, full_disk)
    with pytest.raises(OSError, match="No space left"):
        export(folder, fmt)
    assert out.read_bytes() == before
    assert sorted(p.name for p in folder.iterdir()) == sorted(["reconstruction.npz", out.name])
