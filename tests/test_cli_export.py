"""`physpose export / report / overlay`: files on success, a clear message and exit 2 on bad input."""

from __future__ import annotations

import pytest

import physpose.report as report
from physpose.cli import main
from physpose.errors import PhysposeError
from synthetic_result import save_result


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("cli")
    return {"physics": save_result(tmp / "p", num_frames=6),
            "kinematic": save_result(tmp / "k", num_frames=6, physics=False)}


@pytest.mark.parametrize("fmt, name", [("bvh", "motion.bvh"), ("glb", "motion.glb"),
                                       ("csv", "joints.csv"), ("json", "joints.json"),
                                       ("forces", "forces.csv")])
def test_export_each_format(results, fmt, name, capsys):
    assert main(["export", str(results["physics"]), "--format", fmt]) == 0
    path = results["physics"] / name
    assert capsys.readouterr().out.strip() == str(path) and path.stat().st_size > 0


def test_export_to_a_chosen_file(results, tmp_path):
    out = tmp_path / "deep" / "walk.bvh"
    assert main(["export", str(results["kinematic"]), "-f", "bvh", "--out", str(out)]) == 0
    assert out.read_text().startswith("HIERARCHY")


def test_export_into_a_folder_writes_the_default_name_there(results, tmp_path):
    # (a folder as --out had failed with IsADirectoryError)
    assert main(["export", str(results["kinematic"]), "-f", "csv", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "joints.csv").read_text().startswith("frame")


def test_export_into_a_new_folder_named_with_a_separator_makes_it(results, tmp_path):
    # (such a folder had become a file named like it)
    assert main(["export", str(results["kinematic"]), "-f", "bvh", "--out",
                 str(tmp_path / "new") + "/"]) == 0
    assert (tmp_path / "new" / "motion.bvh").read_text().startswith("HIERARCHY")


def test_export_of_a_reconstruction_in_memory_says_to_save_it_first(results):
    from physpose.export import export
    from physpose.reconstruction import Reconstruction

    rec = Reconstruction.load(results["kinematic"])
    with pytest.raises(PhysposeError, match="export's result must be str or PathLike, not "
                                            "Reconstruction.*save it into one first"):
        export(rec, "bvh")


def test_overlay_video_and_png(results, tmp_path, capsys):
    assert main(["overlay", str(results["physics"]), "--out", str(tmp_path / "o.mp4")]) == 0
    assert "plain background" in capsys.readouterr().out
    assert main(["overlay", str(results["kinematic"]), "--png-frame", "2"]) == 0
    assert (results["kinematic"] / "overlay_2.png").stat().st_size > 0


@pytest.mark.skipif(not report.BUNDLE.is_file(), reason="viewer bundle not built; run make setup")
def test_report(results, capsys):
    assert main(["report", str(results["kinematic"])]) == 0
    assert (results["kinematic"] / "report.html").is_file()


@pytest.mark.parametrize("argv, message", [
    (["export", "{missing}", "-f", "csv"], "result folder not found"),
    (["export", "{empty}", "-f", "glb"], "holds no reconstruction.npz"),
    (["export", "{kinematic}", "-f", "bvh", "--motion", "physics"], "no physics motion"),
    (["report", "{missing}"], "result folder not found"),
    (["report", "{empty}"], "holds no reconstruction.npz"),
    (["overlay", "{missing}"], "result folder not found"),
    (["overlay", "{physics}", "--video", "{missing}/v.mp4"], "file not found"),
    (["overlay", "{physics}", "--png-frame", "99"], "outside the result"),
    (["overlay", "{physics}", "--out", "{empty}"], "--out is a folder"),
    (["report", "{physics}", "--out", "{empty}"], "--out is a folder"),
    (["report", "{physics}", "--out", "{empty}/r.txt"], "--out does not end in .html"),
    (["overlay", "{physics}", "--out", "{empty}/o.txt"], "--out does not end in .mp4"),
    (["overlay", "{physics}", "--png-frame", "0", "--out", "{empty}/o.mp4"],
     "--out does not end in .png"),
    (["export", "{physics}", "-f", "forces", "-o", "{physics}/reconstruction.npz"],
     "forces export to a file that does not end in .csv"),
    (["export", "{physics}", "-f", "glb", "-o", "{empty}/walk.bvh"],
     "glb export to a file that does not end in .glb"),
    (["export", "{physics}", "-f", "bvh", "-o", "{empty}/new"],
     "or a folder (ending in /) to write motion.bvh into"),
])
def test_bad_input_gives_a_message_and_exit_2(results, tmp_path, capsys, argv, message):
    (tmp_path / "empty").mkdir()
    where = {"missing": tmp_path / "nope", "empty": tmp_path / "empty", **results}
    assert main([a.format(**where) for a in argv]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_unknown_format_is_rejected_by_the_parser(results, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["export", str(results["physics"]), "--format", "fbx"])
    assert exit_.value.code == 2
    assert "invalid choice: 'fbx'" in capsys.readouterr().err


def test_a_problem_found_in_the_result_names_its_file(results, capsys):
    """Checks deep in an export know the data, not the file; the command names the file."""
    assert main(["export", str(results["kinematic"]), "-f", "forces"]) == 2
    err = capsys.readouterr().err
    assert f"{results['kinematic'] / 'reconstruction.npz'}: this result holds no simulated" in err


def test_a_result_with_a_malformed_image_size_is_named(results, tmp_path, capsys):
    from physpose.reconstruction import Reconstruction  # noqa: PLC0415

    rec = Reconstruction.load(results["physics"])
    folder = tmp_path / "odd"
    rec.replace(meta={**rec.meta, "image_size": "640x360"}).save(folder / "reconstruction.npz")
    assert main(["overlay", str(folder), "--png-frame", "0"]) == 2
    err = capsys.readouterr().err
    assert f"{folder / 'reconstruction.npz'}: its image_size '640x360' is not" in err
