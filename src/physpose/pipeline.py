"""The whole pipeline: video -> observe -> kinematics -> body -> dynamics -> reconstruction.npz.

``reconstruct(video_or_observations, out_dir, config)`` runs every stage with one composed,
frozen `PipelineConfig` (presets ``fast``, the default, and ``paper``), writes
``reconstruction.npz`` (the contract of DESIGN.md, kinematic and physics fields), the resolved
``config.json`` and keeps the dynamics stage's per-window checkpoints in
``<out_dir>/dynamics_windows`` so an interrupted run resumes.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from physpose import __version__, diagnostics, metrics, supports
from physpose.body import BodyConfig, build_body
from physpose.cache import atomic_path
from physpose.dynamics import PRESETS as DYNAMICS_PRESETS
from physpose.dynamics import DynamicsConfig, PhysicsResult, optimize_dynamics
from physpose.dynamics.optimize import MIN_FRAMES
from physpose.errors import PhysposeError, expect_type
from physpose.kinematics.config import KinematicConfig
from physpose.kinematics.result import KinematicFit
from physpose.keypoints_io import is_keypoints_file, load_keypoints
from physpose.observations import Observations, check_slow_motion
from physpose.observe import ObserveConfig, footage_observe, observe
from physpose.paths import check_output_folder, output_folder
from physpose.reconstruction import Reconstruction
from physpose.scene import SceneConfig

RECONSTRUCTION_FILE = "reconstruction.npz"
CONFIG_FILE = "config.json"
CHECKPOINT_FOLDER = "dynamics_windows"


@dataclass(frozen=True)
class PipelineConfig:
    """Every stage's settings; the kinematic variant defaults to the paper's SO+GT.

    auto_support: where the estimate's feet stay above the floor for longer than a jump
    (diagnostics.raised_runs), add a box under them to the scene (supports.support_boxes);
    where the person sits (supports.seated_runs), a seat (supports.seat_boxes).
    slow_motion: how many times slower than real time the footage plays (4 for 120 fps
    footage played at 30 fps; below 1 for sped-up footage). Every stage after observing then
    runs on the real clock: the kinematic fit, the simulation under real gravity, the output's
    fps, speeds and forces. `observe.target_fps` is then the analysis rate in real time.
    """

    observe: ObserveConfig = field(default_factory=ObserveConfig)
    kinematics: KinematicConfig = field(default_factory=KinematicConfig)
    body: BodyConfig = field(default_factory=BodyConfig)
    scene: SceneConfig = field(default_factory=SceneConfig)
    dynamics: DynamicsConfig = field(default_factory=lambda: DYNAMICS_PRESETS["fast"])
    auto_support: bool = True
    slow_motion: float = 1.0

    def __post_init__(self) -> None:
        for name, kind, example in (
                ("observe", ObserveConfig, "ObserveConfig()"),
                ("kinematics", KinematicConfig, "KinematicConfig.preset('SO+GT')"),
                ("body", BodyConfig, "BodyConfig()"), ("scene", SceneConfig, "SceneConfig()"),
                ("dynamics", DynamicsConfig, "physpose.dynamics.PRESETS['paper']")):
            expect_type(getattr(self, name), kind, f"PipelineConfig.{name}",
                        f"pass a config, e.g. {name}={example}, or use "
                        "PipelineConfig.preset('fast' or 'paper', ...)")
        check_slow_motion(self.slow_motion)

    def footage_observe(self) -> ObserveConfig:
        """The observe settings on the footage's clock: slow-motion footage is sampled
        `slow_motion` times more sparsely, so that the analysis rate holds in real time."""
        return footage_observe(self.observe, self.slow_motion)

    def without_cache(self) -> PipelineConfig:
        """The same settings with the observe and kinematic stages computed afresh, not read
        from the stage cache (the dynamics' windows are reused or not by `resume`)."""
        return dataclasses.replace(
            self, observe=dataclasses.replace(self.observe, use_cache=False),
            kinematics=dataclasses.replace(self.kinematics, use_cache=False))

    @classmethod
    def preset(cls, name: str = "fast", **changes) -> PipelineConfig:
        """``fast`` (default budgets) or ``paper`` (the paper's CMA-ES budget), with overrides."""
        if name not in DYNAMICS_PRESETS:
            raise PhysposeError(f"unknown preset {name!r}",
                                remedy=f"choose one of {', '.join(DYNAMICS_PRESETS)}")
        return dataclasses.replace(cls(dynamics=DYNAMICS_PRESETS[name]), **changes)

    def to_json(self) -> dict:
        return json.loads(json.dumps(dataclasses.asdict(self), default=str))


_log = logging.getLogger(__name__)


def _warn(message: str | None) -> None:
    """Tell the user about a problem in the input (diagnostics.py) as soon as it is known."""
    if message:
        _log.warning(message)


def load_observations(source: str | Path | Observations, cfg: ObserveConfig,
                      progress: bool = True) -> Observations:
    """Observations of a video, a keypoints file (.json/.npz), or given as they are."""
    if isinstance(source, Observations):
        return source
    path = Path(source)
    return load_keypoints(path) if is_keypoints_file(path) else observe(path, cfg,
                                                                        progress=progress)


def trim_unseen_ends(obs: Observations) -> tuple[Observations, list[int] | None]:
    """The observations without the frames before the person comes into view and after they
    leave it (no evidence there: left out rather than invented), and the [first, last] frames
    kept (None where nothing was left out, or too little would be left)."""
    first, last = obs.seen_span()
    if (first, last) == (0, obs.num_frames - 1) or last - first + 1 < MIN_FRAMES:
        return obs, None
    return obs.frames(first, last + 1), [first, last]


def footage_times(obs: Observations, frames, slow_motion: float = 1.0) -> list[float]:
    """Seconds into the footage (what --start/--end take) of the given frames; obs on the real
    clock of footage `slow_motion` times slower."""
    return [round(float(t) * slow_motion, 4) for t in np.asarray(obs.timestamps)[frames]]


def unsure_times(obs: Observations, slow_motion: float = 1.0) -> list[float]:
    """Seconds into the footage of the detections observe left out as torn
    (`Observations.unsure`)."""
    return [] if obs.unsure is None else footage_times(obs, obs.unsure, slow_motion)


def reconstruct(video_or_observations: str | Path | Observations, out_dir: str | Path,
                config: PipelineConfig = PipelineConfig(), *, height: float | None = None,
                mass: float | None = None, resume: bool = True, progress: bool = True
                ) -> Reconstruction:
    """Run every stage and write ``reconstruction.npz`` and ``config.json`` into out_dir.

    Observations given as they are (or read from a keypoints file) are on the footage's clock;
    ``config.slow_motion`` scales them to the real one.

    height (m) and mass (kg) of the person, when known, fix the body's size and weight.
    resume=False discards the dynamics checkpoints of an earlier run in out_dir.
    """
    from physpose.kinematics.fit import fit_kinematics, stderr_log  # noqa: PLC0415 (JAX)

    expect_type(config, PipelineConfig, "reconstruct's config",
                "pass PipelineConfig.preset('fast') or PipelineConfig.preset('paper')")
    out_dir = Path(out_dir)
    check_output_folder(out_dir)
    windows = out_dir / CHECKPOINT_FOLDER
    timings = _Stopwatch()
    obs = load_observations(video_or_observations, config.footage_observe(), progress)
    obs = obs.on_real_clock(config.slow_motion)
    if obs.num_frames < MIN_FRAMES:
        raise PhysposeError(f"only {obs.num_frames} frame{'s' * (obs.num_frames != 1)} to "
                            f"reconstruct motion from (need at least {MIN_FRAMES})",
                            path=obs.source, remedy="use a longer clip, or a wider --start/--end")
    with output_folder(out_dir):  # not made before a check that could refuse the clip
        if not resume and windows.exists():
            shutil.rmtree(windows)
        timings.lap("observe")
        obs, found = _screen_observations(obs, config.slow_motion)
        kin = fit_kinematics(obs, config.kinematics, height=height, mass=mass,
                             progress=progress, **({"log": stderr_log} if progress else {}))
        timings.lap("kinematics")
        scene, found_in_fit = _scene_for(kin, config)
        found |= found_in_fit
        body = build_body(kin.shape, scene, config.body)
        timings.lap("body")
        phys = optimize_dynamics(body, kin, obs, config.dynamics, checkpoint_dir=windows,
                                 progress=progress)
        timings.lap("dynamics")
        found |= _screen_physics(phys, kin.fps, config.dynamics)
        recon = kin.to_reconstruction(obs, body_mjcf=body.xml).replace(
            **phys.reconstruction_fields())
        recon = recon.replace(meta={**recon.meta, "slow_motion": config.slow_motion,
                                    "timings_s": timings.seconds,
                                    "dynamics": {**phys.meta(), "timings": phys.timings},
                                    "physpose_version": __version__, "diagnostics": found})
        recon.save(out_dir / RECONSTRUCTION_FILE)
        resolved = {"stage": "reconstruct", "physpose_version": __version__,
                    "input": obs.source, "height": height, "mass": mass,
                    "config": config.to_json(), "timings_s": timings.seconds}
        with atomic_path(out_dir / CONFIG_FILE) as tmp:
            tmp.write_text(json.dumps(resolved, indent=2) + "\n")
        return recon


class _Stopwatch:
    """Seconds per stage: `lap(stage)` books the time since the previous lap."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self._clock = time.perf_counter()

    def lap(self, stage: str) -> None:
        now = time.perf_counter()
        self.seconds[stage] = now - self._clock
        self._clock = now


def _screen_observations(obs: Observations, slow_motion: float
                         ) -> tuple[Observations, dict]:
    """The observations without their unseen ends, and what the input's checks found
    (meta["diagnostics"]), each problem logged as a warning as soon as it is known."""
    _warn(diagnostics.rate_message(obs.fps))
    observed_frames = obs.num_frames
    unsure = unsure_times(obs, slow_motion)
    _warn(diagnostics.unsure_message(unsure))
    untrimmed = obs
    obs, trimmed = trim_unseen_ends(obs)
    trimmed_times = None if trimmed is None else footage_times(untrimmed, trimmed, slow_motion)
    _warn(diagnostics.trimmed_message(trimmed, observed_frames, obs.fps, trimmed_times))
    _warn(diagnostics.camera_message(obs.camera_motion))
    jumps = diagnostics.person_jumps(obs.keypoints2d, obs.detected, obs.fps)
    jump_times = footage_times(obs, jumps, slow_motion)
    _warn(diagnostics.jumps_message(jumps, obs.fps, jump_times))
    keypoints = obs.frame_keypoints()
    hidden_feet = diagnostics.hidden_feet_share(keypoints, obs.valid, obs.image_size)
    _warn(diagnostics.hidden_feet_message(hidden_feet))
    stride = diagnostics.stride_period(keypoints, obs.valid, obs.fps)
    _warn(diagnostics.slow_stride_message(stride, slow_motion))
    return obs, {"trimmed": trimmed, "trimmed_times": trimmed_times,
                 "observed_frames": observed_frames,
                 "camera_motion": obs.camera_motion, "unsure_detections": unsure,
                 "person_jumps": jumps, "person_jump_times": jump_times,
                 "hidden_feet": hidden_feet, "stride_period": stride}


def _scene_for(kin: KinematicFit, config: PipelineConfig) -> tuple[SceneConfig, dict]:
    """The configured scene plus the supports and seats the estimate asks for (with
    config.auto_support), and what was found (meta["diagnostics"]); problems are logged."""
    camera_height = metrics.camera_height(kin.T_world2cam)
    camera_tilt = metrics.camera_tilt(kin.T_world2cam)
    _warn(diagnostics.camera_pose_message(camera_height, camera_tilt))
    raised = diagnostics.raised_runs(kin.joints, kin.fps)
    boxes = supports.support_boxes(kin.joints, raised, kin.fps, kin.support_heights) \
        if config.auto_support else ()
    _warn(diagnostics.raised_message(raised, kin.fps, supported=bool(boxes)))
    seated = supports.seated_runs(kin.joints, kin.fps)
    seats = supports.seat_boxes(kin.joints, seated) if config.auto_support else ()
    _warn(diagnostics.seated_message(seated, seats, kin.fps))
    found = {"camera_height": camera_height, "camera_tilt": camera_tilt,
             "label_exchanges": kin.label_exchanges,
             "raised": [list(r) for r in raised],
             "supports": [[*b.center, *b.size] for b in boxes],
             "seated": [list(r) for r in seated], "seats": [b.spec() for b in seats]}
    if not (boxes or seats):
        return config.scene, found
    return dataclasses.replace(config.scene,
                               obstacles=config.scene.obstacles + boxes + seats), found


def _screen_physics(phys: PhysicsResult, fps: float, config: DynamicsConfig) -> dict:
    """Windows without a valid sample and forces the simulation did not record
    (meta["diagnostics"]), logged."""
    invalid = diagnostics.invalid_window_runs(phys.windows, sequential=not config.independent)
    _warn(diagnostics.invalid_message(invalid, fps))
    unrecorded = diagnostics.unrecorded_force_runs(phys.grf)
    _warn(diagnostics.unrecorded_forces_message(unrecorded, fps))
    return {"invalid_windows": [list(r) for r in invalid],
            "unrecorded_forces": [list(r) for r in unrecorded]}
