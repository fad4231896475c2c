"""demo_data: the set-up's fetch of the demo files from registry wheels (pip faked here)."""

from __future__ import annotations

import subprocess
import zipfile
from pathlib import Path

from physpose import demo_data


def _fake_pip(calls: list):
    """Stands in for `pip download`: writes a sports2d wheel holding the demo video."""
    def run(cmd, **kwargs):
        calls.append(cmd)
        folder = Path(cmd[cmd.index("-d") + 1])
        with zipfile.ZipFile(folder / "sports2d-0-py3-none-any.whl", "w") as zf:
            zf.writestr("Sports2D/Demo/demo.mp4", b"video bytes")
        return subprocess.CompletedProcess(cmd, 0, "", "")
    return run


def test_files_are_fetched_once_and_again_when_one_is_missing(tmp_path, monkeypatch):
    calls: list = []
    monkeypatch.setattr(demo_data.subprocess, "run", _fake_pip(calls))
    root = demo_data.ensure_sports2d_demo(tmp_path, quiet=True)
    assert (root / "demo.mp4").read_bytes() == b"video bytes" and len(calls) == 1
    demo_data.ensure_sports2d_demo(tmp_path, quiet=True)
    assert len(calls) == 1  # the marker and the files are there
    (root / "demo.mp4").unlink()
    demo_data.ensure_sports2d_demo(tmp_path, quiet=True)
    assert (root / "demo.mp4").is_file() and len(calls) == 2
