"""Shared fixtures: locations of the real evaluation material, skipped cleanly when absent, and
a simulated standing motion."""

from __future__ import annotations

from pathlib import Path

import pytest

from physpose.paths import pose2sim_demo_dir, shared_data_dir, sports2d_demo_dir


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """../shared/data (real videos and mocap); skips the test when it is absent."""
    root = shared_data_dir()
    if not (root / "README.md").is_file():
        pytest.skip(f"evaluation material not found at {root} (see ../shared/data/README.md)")
    return root


@pytest.fixture(scope="session")
def pose2sim_demo() -> Path:
    """The pose2sim demo fetched by `make setup`; skips when it was not fetched."""
    root = pose2sim_demo_dir()
    if not (root / "videos" / "cam01.mp4").is_file():
        pytest.skip(f"pose2sim demo not found at {root}; run `make data`")
    return root


@pytest.fixture(scope="session")
def sports2d_demo() -> Path:
    """Sports2D's two-person demo video fetched by `make setup`; skips when it was not fetched."""
    video = sports2d_demo_dir() / "demo.mp4"
    if not video.is_file():
        pytest.skip(f"sports2d demo not found at {video}; run `make data`")
    return video


@pytest.fixture(scope="session")
def standing() -> tuple:
    """(joints (T, 21, 3), fps) of 2 s of simulated quiet standing (dynamics.synthetic)."""
    from physpose.body import build_body  # noqa: PLC0415
    from physpose.dynamics.synthetic import simulated_clip  # noqa: PLC0415
    from physpose.shape import BodyShape  # noqa: PLC0415

    fit, _, _ = simulated_clip(build_body(BodyShape.from_height(1.7)), "stand", seconds=2.0)
    return fit.joints, fit.fps
