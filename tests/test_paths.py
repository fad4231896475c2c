"""paths.check_output_folder: an output folder that cannot be written is refused up front."""

from __future__ import annotations

import os

import pytest

from physpose.cli import main
from physpose.errors import PhysposeError
from physpose.paths import check_output_folder


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
