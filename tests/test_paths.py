"""paths.check_output_folder: an output folder that cannot be written is refused up front;
paths.output_folder: a failed run leaves no empty folder behind."""

from __future__ import annotations

import os

import pytest

from physpose.cli import main
from physpose.errors import PhysposeError
from physpose.paths import check_output_folder, output_folder


def test_a_new_or_existing_folder_passes_and_nothing_is_created(tmp_path):
    assert check_output_folder(tmp_path) == tmp_path
    new = tmp_path / "a" / "b"
    assert check_output_folder(new) == new
    assert not (tmp_path / "a").exists()


def test_a_file_on_the_way_is_refused(tmp_path):
    blocker = tmp_path / "notes.txt"
    blocker.write_text("")
    with pytest.raises(PhysposeError, match="exists and is not a folder"):
        check_output_folder(blocker)
    with pytest.raises(PhysposeError, match=f"{blocker} is a file"):
        check_output_folder(blocker / "run", option="--out")


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write anywhere")
def test_a_folder_without_write_permission_is_refused(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o555)
    with pytest.raises(PhysposeError, match="cannot write into"):
        check_output_folder(locked / "run")


def test_benchmark_refuses_its_out_before_any_work(tmp_path, capsys):
    """A wrong --out is found before the material is even looked for (a benchmark can run
    for hours, and its results were written only at the end)."""
    blocker = tmp_path / "results"
    blocker.write_text("")
    assert main(["benchmark", "--video", str(tmp_path / "missing.mp4"), "--out",
                 str(blocker)]) == 2
    err = capsys.readouterr().err
    assert "is not a folder" in err and "missing.mp4" not in err


def test_a_failed_run_takes_away_the_empty_folders_it_made(tmp_path):
    out = tmp_path / "runs" / "walk"
    with pytest.raises(RuntimeError), output_folder(out) as made:
        assert made == out and out.is_dir()
        (out / "dynamics_windows").mkdir()
        raise RuntimeError("stage failed")
    assert not (tmp_path / "runs").exists()


def test_a_failed_run_keeps_what_it_wrote_and_what_was_there(tmp_path):
    out = tmp_path / "walk"
    with pytest.raises(RuntimeError), output_folder(out):
        (out / "dynamics_windows").mkdir()
        (out / "dynamics_windows" / "window_000.npz").write_bytes(b"x")
        (out / "empty").mkdir()
        raise RuntimeError("stage failed")
    assert (out / "dynamics_windows" / "window_000.npz").is_file()  # a resume starts here
    assert not (out / "empty").exists()
    before = tmp_path / "old"
    (before / "inner").mkdir(parents=True)
    with pytest.raises(RuntimeError), output_folder(before):
        raise RuntimeError("stage failed")
    assert (before / "inner").is_dir()  # not made by this run: left alone


def test_a_run_that_succeeds_keeps_its_folder(tmp_path):
    with output_folder(tmp_path / "walk") as out:
        pass
    assert out.is_dir()
