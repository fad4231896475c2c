"""`physpose body`: the MJCF it writes, the picture, and its error messages."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from physpose.cli import main


def test_writes_a_loadable_model(tmp_path, capsys):
    out = tmp_path / "sub" / "body.xml"
    assert main(["body", "--height", "1.8", "--mass", "80", "--ground-friction", "0.6",
                 "--obstacle", "box:-0.5,0,0.225,0.45,0.45,0.45", "--obstacle",
                 "box:0.8,0,0.1,0.4,1,0.2,15", "--out", str(out)]) == 0
    assert "48 actuated dof" in capsys.readouterr().out
    m = mujoco.MjModel.from_xml_path(str(out))
    assert m.nu == 48 and m.nkey == 1
    assert m.body_mass.sum() == pytest.approx(80.0, rel=1e-5)
    floor = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    assert m.geom_friction[floor, 0] == pytest.approx(0.6)
    assert mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "obstacle_1") >= 0


def test_trampoline_and_direct_ground(tmp_path):
    for extra, solref in ((["--trampoline"], None), (["--ground-stiffness", "400",
                                                      "--ground-damping", "5"], [-400, -5])):
        out = tmp_path / "b.xml"
        assert main(["body", "--height", "1.7", *extra, "--out", str(out)]) == 0
        m = mujoco.MjModel.from_xml_path(str(out))
        got = m.geom_solref[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor")]
        assert got[0] < 0 and (solref is None or np.allclose(got, solref))


def test_png(tmp_path):
    png = tmp_path / "body.png"
    assert main(["body", "--height", "1.6", "--out", str(tmp_path / "b.xml"), "--png",
                 str(png)]) == 0
    import matplotlib.image
    image = matplotlib.image.imread(png)
    assert image.shape[0] > 100 and image[..., :3].std() > 0.05  # a picture, not a blank


@pytest.mark.parametrize("args, message", [
    (["--height", "3"], "--height 3 m is outside 0.5-2.5 m"),
    (["--height", "1.7", "--mass", "10"], "--mass 10 kg is outside 20-300 kg"),
    (["--height", "1.7", "--obstacle", "box:1,2"], "--obstacle #1"),
    (["--height", "1.7", "--ground-friction", "-1"], "--ground-friction"),
    (["--height", "1.7", "--ground-stiffness", "0"], "stiffness"),
    (["--height", "1.7", "--ground-friction", "nan"], "--ground-friction nan is not"),
    (["--height", "1.7", "--png", "body.txt"], "--png does not end in .png"),
])
def test_errors_name_the_argument(tmp_path, capsys, args, message):
    assert main(["body", *args, "--out", str(tmp_path / "b.xml")]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "b.xml").exists()


def test_an_output_path_the_file_system_refuses_is_an_error_not_a_traceback(tmp_path, capsys):
    """An --out below a plain file, or naming a folder, is refused before the work, naming
    the path (it had been the file system's bare "Is a directory")."""
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    assert main(["body", "--height", "1.7", "--out", str(blocker / "b.xml")]) == 2
    err = capsys.readouterr().err
    assert f"{blocker} is a file" in err and "Traceback" not in err
    assert main(["body", "--height", "1.7", "--out", str(tmp_path)]) == 2
    assert "--out is a folder; it names the file to write" in capsys.readouterr().err


def _raising(exc):
    def run(args):
        raise exc
    return run


def test_ctrl_c_and_a_full_disk_end_in_a_message_with_what_to_do(monkeypatch, tmp_path, capsys):
    """Any command: an interrupt prints on a line of its own (a progress bar may hold the
    cursor) and says how to resume; a full disk says to free space, not to check the path."""
    import errno

    import physpose.cli.body as body_cli

    monkeypatch.setattr(body_cli, "_run", _raising(KeyboardInterrupt()))
    assert main(["body", "--height", "1.7", "--out", str(tmp_path / "b.xml")]) == 130
    err = capsys.readouterr().err
    assert err.startswith("\nphyspose body: interrupted. Run the same command again to resume")
    full = OSError(errno.ENOSPC, "No space left on device", str(tmp_path / "w.npz"))
    monkeypatch.setattr(body_cli, "_run", _raising(full))
    assert main(["body", "--height", "1.7", "--out", str(tmp_path / "b.xml")]) == 2
    err = capsys.readouterr().err
    assert f"{tmp_path / 'w.npz'}: No space left on device. free some space there" in err
    assert "check that the path exists" not in err
