"""The README's first command: `physpose demo` runs every stage on the built-in clip."""

import pytest

from physpose.cli import main
from physpose.reconstruction import Reconstruction


@pytest.mark.slow
def test_demo_reconstructs_the_builtin_clip_and_says_where_the_report_is(pose2sim_demo, tmp_path,
                                                                         capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert str((out / "report.html").resolve()) in text
    for name in ("reconstruction.npz", "metrics.json", "report.html", "overlay.mp4",
                 "motion.bvh", "motion.glb", "joints.csv", "config.json"):
        assert (out / name).is_file(), name
    rec = Reconstruction.load(out)
    assert rec.has_physics and rec.num_frames == 42


def test_demo_refuses_an_output_it_could_not_write_before_any_work(tmp_path, capsys,
                                                                    monkeypatch):
    import physpose.cli.demo as demo

    def no_work():
        raise AssertionError("the demo started its work")

    monkeypatch.setattr(demo, "ensure_pose2sim_demo", no_work)
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    assert main(["demo", "--out", str(blocker)]) == 2
    err = capsys.readouterr().err
    assert "is not a folder" in err and "Traceback" not in err
