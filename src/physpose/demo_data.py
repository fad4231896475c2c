"""Fetch the built-in demo inputs from registry packages at set-up time.

- The PyPI package `pose2sim` (BSD-3-Clause) ships a real subject filmed in a motion-capture lab
  by four synchronised cameras with a Qualisys calibration: the demo clip.
- The PyPI package `sports2d` (BSD-3-Clause) ships a real outdoor video with two people (a man
  standing on a box who somersaults off it, a woman walking past): the test of following one
  person (subject.py).

We download each wheel without dependencies and extract only the files used into the
git-ignored data folder. Run: `python -m physpose.demo_data`.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

from physpose.errors import PhysposeError
from physpose.paths import pose2sim_demo_dir, sports2d_demo_dir

POSE2SIM_VERSION = "0.10.49"
_POSE2SIM_PREFIX = "Pose2Sim/Demo_SinglePerson/"
_POSE2SIM_FILES = tuple(f"videos/cam0{i}.mp4" for i in range(1, 5)) + ("calibration/Calib.qca.txt",)
SPORTS2D_VERSION = "0.8.34"
_SPORTS2D_PREFIX = "Sports2D/Demo/"
_SPORTS2D_FILES = ("demo.mp4",)
_MARKER = ".complete"


def demo_videos(root: Path | None = None) -> list[Path]:
    """The four demo views, cam01..cam04."""
    root = root or pose2sim_demo_dir()
    return [root / w for w in _POSE2SIM_FILES if w.endswith(".mp4")]


def ensure_pose2sim_demo(root: Path | None = None, *, quiet: bool = False) -> Path:
    """Make sure the demo files exist under `root` (default: data/pose2sim/Demo_SinglePerson)."""
    return _ensure("pose2sim", POSE2SIM_VERSION, _POSE2SIM_PREFIX, _POSE2SIM_FILES,
                   root or pose2sim_demo_dir(), "the demo clip, ~50 MB", quiet)


def ensure_sports2d_demo(root: Path | None = None, *, quiet: bool = False) -> Path:
    """Make sure Sports2D's two-person demo video exists under `root` (default:
    data/sports2d); returns the folder."""
    return _ensure("sports2d", SPORTS2D_VERSION, _SPORTS2D_PREFIX, _SPORTS2D_FILES,
                   root or sports2d_demo_dir(), "a two-person test video, ~9 MB", quiet)


def _ensure(package: str, version: str, prefix: str, wanted: tuple[str, ...], root: Path,
            what: str, quiet: bool) -> Path:
    marker = root / _MARKER
    if marker.is_file() and marker.read_text().strip() == version \
            and all((root / rel).is_file() for rel in wanted):  # a file deleted since: fetch
        return root
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--disable-pip-version-check",
               "--quiet", f"{package}=={version}", "-d", tmp]
        if not quiet:
            print(f"fetching {what}: {package}=={version} (files kept: {len(wanted)})")
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            raise PhysposeError(f"could not download {package}=={version}: "
                                f"{proc.stderr.strip()[-500:]}",
                                remedy="check that the package registry is reachable and pip is "
                                       "installed in the environment (`make setup`)")
        wheels = list(Path(tmp).glob(f"{package}-*.whl"))
        if not wheels:
            raise PhysposeError(f"pip reported success but no {package} wheel was saved",
                                path=tmp, remedy="retry `make data`")
        _extract(wheels[0], prefix, wanted, root, f"{package}=={version}")
    marker.write_text(version + "\n")
    return root


def _extract(wheel: Path, prefix: str, wanted: tuple[str, ...], root: Path, pin: str) -> None:
    with zipfile.ZipFile(wheel) as zf:
        names = set(zf.namelist())
        for rel in wanted:
            member = prefix + rel
            if member not in names:
                raise PhysposeError(f"the wheel lacks {member}", path=wheel, remedy=f"pin {pin}")
            target = root / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(zf.read(member))


if __name__ == "__main__":
    try:
        print(ensure_pose2sim_demo())
        print(ensure_sports2d_demo())
    except PhysposeError as err:
        sys.exit(f"error: {err}")
