"""Fetch the built-in demo input: the pose2sim single-person clip (4 calibrated views).

The PyPI package `pose2sim` (BSD-3-Clause) ships a real subject filmed in a motion-capture lab
by four synchronised cameras with a Qualisys calibration. We download its wheel without
dependencies at set-up time and extract only the videos and the calibration into the
git-ignored data folder. Run: `python -m physpose.demo_data`.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

from physpose.errors import PhysposeError
from physpose.paths import pose2sim_demo_dir

POSE2SIM_VERSION = "0.10.49"
_PREFIX = "Pose2Sim/Demo_SinglePerson/"
_WANTED = tuple(f"videos/cam0{i}.mp4" for i in range(1, 5)) + ("calibration/Calib.qca.txt",)
_MARKER = ".complete"


def demo_videos(root: Path | None = None) -> list[Path]:
    """The four demo views, cam01..cam04."""
    root = root or pose2sim_demo_dir()
    return [root / w for w in _WANTED if w.endswith(".mp4")]


def ensure_pose2sim_demo(root: Path | None = None, *, quiet: bool = False) -> Path:
    """Make sure the demo files exist under `root` (default: data/pose2sim/Demo_SinglePerson)."""
    root = root or pose2sim_demo_dir()
    marker = root / _MARKER
    if marker.is_file() and marker.read_text().strip() == POSE2SIM_VERSION:
        return root
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--disable-pip-version-check",
               "--quiet", f"pose2sim=={POSE2SIM_VERSION}", "-d", tmp]
        if not quiet:
            print(f"fetching the demo clip: pose2sim=={POSE2SIM_VERSION} (~50 MB, files kept: 5)")
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            raise PhysposeError(f"could not download pose2sim=={POSE2SIM_VERSION}: "
                                f"{proc.stderr.strip()[-500:]}",
                                remedy="check that the package registry is reachable and pip is "
                                       "installed in the environment (`make setup`)")
        wheels = list(Path(tmp).glob("pose2sim-*.whl"))
        if not wheels:
            raise PhysposeError("pip reported success but no pose2sim wheel was saved",
                                path=tmp, remedy="retry `make data`")
        _extract(wheels[0], root)
    marker.write_text(POSE2SIM_VERSION + "\n")
    return root


def _extract(wheel: Path, root: Path) -> None:
    with zipfile.ZipFile(wheel) as zf:
        names = set(zf.namelist())
        for rel in _WANTED:
            member = _PREFIX + rel
            if member not in names:
                raise PhysposeError(f"the wheel lacks {member}", path=wheel,
                                    remedy=f"pin pose2sim=={POSE2SIM_VERSION}")
            target = root / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(zf.read(member))


if __name__ == "__main__":
    try:
        print(ensure_pose2sim_demo())
    except PhysposeError as err:
        sys.exit(f"error: {err}")
