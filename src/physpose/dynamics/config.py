"""Configuration of the trajectory optimisation: `DynamicsConfig`, its presets and the ablations.

``PRESETS["fast"]`` is the default, ``PRESETS["paper"]`` the paper's budget; ``ablated(config,
name)`` removes the objective terms of one row of the paper's Table 2 (bottom half). The fields
that change one seed's windows are part of a run's checkpoint key
(``DynamicsConfig.window_identity``).
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass, field

import numpy as np

from physpose.dynamics.balance import BalanceGains
from physpose.dynamics.controller import ControllerGains
from physpose.dynamics.ilqr import RefineConfig
from physpose.dynamics.objective import ObjectiveWeights
from physpose.dynamics.travel import CAMERA_SETTINGS
from physpose.errors import PhysposeError, check_field, expect_type

# Hinges whose targets CMA-ES varies (optimize.searched_dofs).
SEARCH_SETS = ("all", "legs_trunk", "legs")
# The refinement's keep ratio while it was fixed (stops 36-37): checkpoints made then have no
# keep_ratio in their key, so only this value may leave it out, whatever the default becomes.
UNKEYED_KEEP_RATIO = 1.5


def available_cores() -> int:
    """The CPU cores this process may run on (its affinity where the system reports one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # macOS and Windows have no affinity call
        return max(1, os.cpu_count() or 1)


@dataclass(frozen=True)
class DynamicsConfig:
    """Settings of the trajectory optimisation.

    window, overlap: s (paper: 1 s windows; a window is at least knot_spacing long).
    independent: optimise windows from the kinematic state and join them (parallel_windows
    searched side by side). knot_spacing: s between servo-target spline knots.
    reference_knot_spacing: s, low-pass of the kinematic estimate for the initial state and
    targets. popsize, iterations: CMA-ES samples per iteration and iterations per window;
    sigma0: rad, initial step size; diagonal: diagonal covariance (sep-CMA) instead of full.
    max_root_distance: m, a sample whose root strays further from the kinematic root is
    invalid; max_penetration: m below the floor. contact_height: m, sole points this close to
    the floor may push in the initial inverse dynamics; ground_snap: m,
    an initial state hovering less than this is put down on the floor; ground_reference: do
    the same to every frame of the estimate before it gives the initial targets and the COM
    targets (a foot inside the floor would stub it; a sunken body asks for bent knees).
    flat_stance: in that grounded reference, lay standing feet flat on the floor by leg
    inverse kinematics (stance.py), so the body stands on whole soles rather than box edges.
    balance: closed-loop COM feedback through the standing feet's ankles inside every rollout
    (balance.py; off while its frequency is 0).
    start_sight_smoothing: s; a window started from the estimate (the clip's first, a restart,
        every independent window) takes its root's horizontal velocity along the camera's line
        of sight low-passed by a Gaussian of this sd (0: as the reference has it). The
        estimate's depth is its noisiest part, and a body started with a depth speed that is
        noise carries it away from the estimate (docs/dynamics.md, Start velocity along the
        line of sight: measured at 0.25 s, off in both presets).
    tracking_start: also simulate each window once under the whole-body tracking controller
    (controller.py, gains ``controller``) and, when its targets score better than the
    inverse-dynamics ones, search spline offsets on top of them (exactly reproduced).
    retries, retry_distance: a sequential window whose result hands on a state with the COM
    more than retry_distance (m) from the estimate's is searched again (another seed, 1.5x the
    step size), at most retries times. reset_distance: if the kept result still hands on a COM
    further than this (m) from the estimate's, the next window restarts from the kinematic
    state (a discontinuity instead of a fall that would carry on; recorded as reset_after); a
    window whose COM strays this far at an earlier kept frame is cut there and a window from
    that frame restarts (recorded as cut_at).
    fall_distance: m; a window is also cut where the simulated head is more than this below
    the estimate's: a fall under way, which a body going down beside an estimate near the floor
    (a roll, a get-up) shows in its head before its COM strays reset_distance. Infinite: the
    COM alone decides, as before stop 79.
    refine_within: m; with the refinement on, an attempt whose search hands on a COM further
    than this from the estimate's is refined only if it is kept: the refinement moves the
    handover by 8 mm (median), and none of 82 attempts searched beyond 0.3 m came within the
    retry distance (docs/dynamics.md, Fewer attempts refined, one retry). Infinite: every
    attempt is refined, as before stop 41.
    retry_within: m; an attempt whose search hands on a COM further than this from the
    estimate's (or an invalid state) is not retried: in stop 41's runs, retries after a first
    search beyond 0.5 m (or invalid) brought 1 of 40 windows within the retry distance and
    took 13 % of the windows' time; infinite (retried whatever the miss) in both presets, as
    0.5 m cost a real video its foot-skate bound (docs/dynamics.md, Hopeless windows).
    search: "all" hinges, "legs_trunk" (hips, knees, ankles, spine, thorax: what balance
    needs; arms, neck and head keep their inverse-dynamics targets), or "legs" (hips, knees,
    ankles; the trunk keeps its start targets too). searches: CMA-ES searches of each window
    side by side under other seeds, from the same start; the average of their results is kept
    unless it is invalid or worse than all of them (their offsets from the start are mostly
    uncorrelated random walk, which the average cancels). candidates: whole-clip optimisations
    with seeds seed, seed + 1, ...; the one with the lowest mean window loss is kept
    (open-loop balance is chaotic: the same clip drifts under one seed and not under another,
    and a lower loss goes with a lower error; docs/dynamics.md). seed: CMA-ES seed.
    place_stretches: move each continuous simulated stretch (between restarts) horizontally so
        that its COM matches the estimate's on average (sequential runs on a floor without
        obstacles, where the moved stretch is the same simulation; stretches.py).
    camera: "still" (the default) takes the camera as standing still; "travelling" follows a
        camera that travelled with the person: the estimate is moved on by the camera's path,
        read off its standing feet, and the re-projection term moves the simulated body back
        by it (travel.py); "auto" does so where the observe stage found the camera moving
        (Observations.camera_motion "moving"). Not the default: on the material at hand it
        did not lower the restarts or the image error (docs/dynamics.md).
    swing_confidence: weight the ``swing`` term, foot by foot and frame by frame, by the
        detections' mean confidence of the foot's ankle, heel and toe (a step the detector
        barely sees is asked for less; measured in docs/dynamics.md, Swing feet weighted by
        the detector's confidence).
    refine: iLQR refinement of each window's result after its search (ilqr.py; off while its
        iterations are 0).
    nthread: rollout threads (does not change results); default, the cores this process may
        use. benchmarks/bench_threads.py on a 16-core machine: 2.4x the speed of 2 threads.
    """

    # 1.5 s windows (handover after 0.4 or 0.6 s) were further from the truth on motion capture;
    # a handover after 0.2 s, at 1.4x the time, was no nearer there, and its lower foot skate on
    # the real clips under one seed did not hold under another (docs/dynamics.md, Windows).
    window: float = 1.0
    overlap: float = 0.6
    independent: bool = False
    parallel_windows: int = 4
    knot_spacing: float = 0.1
    reference_knot_spacing: float = 0.1
    popsize: int = 24
    iterations: int = 30
    sigma0: float = 0.03
    diagonal: bool = True
    weights: ObjectiveWeights = field(default_factory=ObjectiveWeights)
    max_root_distance: float = 1.0
    max_penetration: float = 0.1
    contact_height: float = 0.03
    ground_snap: float = 0.03
    ground_reference: bool = True
    flat_stance: bool = True
    start_sight_smoothing: float = 0.0
    tracking_start: bool = False
    controller: ControllerGains = field(default_factory=ControllerGains)
    balance: BalanceGains = field(default_factory=BalanceGains)
    retries: int = 2
    retry_distance: float = 0.15
    # 0.15 (= retry_distance) rather than 0.3: on 8 motion-capture clips it cut MPJPE-G on
    # punch 627 -> 194, roll 438 -> 381, jump 402 -> 360, 131_03 235 -> 156 mm, no clip worse;
    # 0.10 was no better (docs/dynamics.md).
    reset_distance: float = 0.15
    fall_distance: float = math.inf
    refine_within: float = 0.3
    retry_within: float = math.inf
    search: str = "legs_trunk"
    searches: int = 1
    candidates: int = 1
    place_stretches: bool = True
    seed: int = 0
    camera: str = "still"
    swing_confidence: bool = True
    refine: RefineConfig = field(default_factory=RefineConfig)
    nthread: int = field(default_factory=available_cores)

    def __post_init__(self) -> None:
        for name, kind in (("weights", ObjectiveWeights), ("controller", ControllerGains),
                           ("balance", BalanceGains), ("refine", RefineConfig)):
            expect_type(getattr(self, name), kind, f"dynamics config {name}",
                        f"pass e.g. {name}={kind.__name__}(...)")
        for name in ("popsize", "iterations", "parallel_windows", "nthread", "candidates",
                     "searches", "retries", "seed"):
            value = getattr(self, name)
            check_field(self, name, isinstance(value, (int, np.integer))
                        and not isinstance(value, bool), "a whole number")
        positive = ("window", "knot_spacing", "reference_knot_spacing", "sigma0",
                    "max_root_distance", "max_penetration")
        for name in positive:
            if not getattr(self, name) > 0:
                raise PhysposeError(f"dynamics config {name}={getattr(self, name)} must be > 0",
                                    remedy="use a preset (fast or paper) or positive values")
        for name in ("window", "knot_spacing", "reference_knot_spacing", "sigma0"):
            check_field(self, name, math.isfinite(getattr(self, name)), "finite")
        for name in ("contact_height", "ground_snap"):
            check_field(self, name, getattr(self, name) >= 0, ">= 0 (m)")
        check_field(self, "popsize", self.popsize >= 2, "at least 2 (CMA-ES ranks its samples)")
        if not 0 <= self.overlap < self.window:
            raise PhysposeError(f"dynamics overlap {self.overlap} s must be in [0, window)",
                                remedy="choose an overlap shorter than the window")
        if self.window < self.knot_spacing:
            raise PhysposeError(f"dynamics window {self.window} s is shorter than the knot "
                                f"spacing {self.knot_spacing} s: it could hold no control "
                                "coefficient of its own",
                                remedy="choose a window at least as long as the knot spacing")
        for name in ("popsize", "parallel_windows", "nthread", "candidates", "searches"):
            if getattr(self, name) < 1:
                raise PhysposeError(f"dynamics config {name} must be >= 1",
                                    remedy="use a preset (fast or paper)")
        if self.search not in SEARCH_SETS:
            raise PhysposeError(f"dynamics search {self.search!r} is unknown",
                                remedy=f"use one of {SEARCH_SETS}")
        if not self.refine_within > 0:
            raise PhysposeError(f"dynamics refine_within={self.refine_within} must be > 0",
                                remedy="use e.g. 0.3 (m), or inf to refine every attempt")
        if not self.retry_within > 0:
            raise PhysposeError(f"dynamics retry_within={self.retry_within} must be > 0",
                                remedy="use e.g. 0.5 (m), or inf to retry whatever the miss")
        if self.retries < 0 or not self.retry_distance > 0 or not self.reset_distance > 0:
            raise PhysposeError(f"dynamics retries={self.retries} must be >= 0, retry_distance="
                                f"{self.retry_distance} and reset_distance={self.reset_distance}"
                                " > 0", remedy="use e.g. retries=2, retry_distance=0.15, "
                                "reset_distance=0.15")
        if not self.fall_distance > 0:
            raise PhysposeError(f"dynamics fall_distance={self.fall_distance} must be > 0",
                                remedy="use e.g. 0.15 (m), or inf to cut on the COM alone")
        if self.camera not in CAMERA_SETTINGS:
            raise PhysposeError(f"dynamics camera {self.camera!r} is unknown",
                                remedy=f"use one of {CAMERA_SETTINGS}")
        if self.iterations < 0:
            raise PhysposeError("dynamics iterations must be >= 0", remedy="use e.g. 20")
        if not self.start_sight_smoothing >= 0:
            raise PhysposeError(f"dynamics start_sight_smoothing={self.start_sight_smoothing} "
                                "must be >= 0", remedy="use e.g. 0.25 (s), or 0 to switch it off")

    def identity(self) -> dict:
        """The fields that change results (everything but the thread count; ``camera`` only
        through what it resolves to for a clip, which the run's inputs carry)."""
        out = dataclasses.asdict(self)
        out.pop("nthread")
        out.pop("camera")
        if not self.balance.enabled:
            out.pop("balance")  # switched off: the same runs (and checkpoints) as before it
        if self.weights.swing == 0:
            out["weights"].pop("swing")  # likewise the swing term (added in stop 21)
        if self.weights.swing == 0 or not self.swing_confidence:
            out.pop("swing_confidence")  # likewise (added in stop 33; moot without the term)
        if self.searches == 1:
            out.pop("searches")  # likewise one search per window (averaging added in stop 25)
        if self.retries == 0 or self.retry_within == math.inf:
            out.pop("retry_within")  # likewise retried whatever the miss (stop 42)
        if not self.refine.enabled or self.refine_within == math.inf:
            out.pop("refine_within")  # likewise every attempt refined (stop 41)
        if self.fall_distance == math.inf:
            out.pop("fall_distance")  # likewise cut on the COM alone (stop 79)
        if self.start_sight_smoothing == 0:
            out.pop("start_sight_smoothing")  # likewise start velocities unsmoothed (stop 48)
        if not self.refine.enabled:
            out.pop("refine")  # likewise no iLQR refinement (added in stop 36)
        else:
            if self.refine.keep_ratio == UNKEYED_KEEP_RATIO:
                out["refine"].pop("keep_ratio")  # likewise the keep test before it was a setting
            if self.refine.root_depth == 0:
                out["refine"].pop("root_depth")  # likewise no depth term (stop 41)
            if self.refine.handover == 1.0:
                out["refine"].pop("handover")  # likewise the handover state unweighted (stop 52)
        return out

    def window_identity(self) -> dict:
        """The fields that change one seed's optimised windows: the checkpoint key's config.
        `candidates` only says how many seeds to try, and the stretches are placed after the
        windows, so neither is in it."""
        out = self.identity()
        for name in ("candidates", "place_stretches"):
            out.pop(name)
        return out


PRESETS: dict[str, DynamicsConfig] = {
    # Tracking start on: on 4 motion-capture clips it cut MPJPE-G on three. One candidate: two
    # (twice the time) helped on motion capture but not on real detections (docs/dynamics.md).
    # No balance feedback: on the whole benchmark over two seeds it changed no figure by more
    # than its seed noise (docs/dynamics.md); it stays an option (balance, --balance-hz).
    # No COM term (the paper's weight is 15): over the whole benchmark and two seeds it cost
    # pose accuracy everywhere (MPJPE-PA 6-7 mm, MPJPE-2d 3-10 px) while the restarts from the
    # estimate keep the body near it; the price is more restarts (docs/dynamics.md, Presets).
    # Swing feet (a term of physpose's own, weight 12): on motion capture under two seeds it
    # lowered MPJPE-G by about 8 mm and the velocity error by 0.04-0.05 m/s, the feet sliding a
    # little more; on pose2sim MPJPE-PA rose by 2-3 mm, skate fell (docs/dynamics.md, Swing feet).
    # Its swing feet weighted by the detections' confidence in them (swing_confidence, on by
    # default): on pose2sim MPJPE-G fell on all four views (-5.0 +- 1.5 mm), motion capture
    # unchanged within its noise (docs/dynamics.md, Swing feet weighted by the detector's
    # confidence).
    # Six iLQR iterations after each window's search (refine, ilqr.py; stop 37): on the 15
    # motion-capture clips 2.0 restarts per clip instead of 3.1, the other figures within
    # their noise; on the everyday motions nearer the truth (MPJPE-G -10 mm, velocity error
    # and skate lower), on the athletic ones a little further; 1.44x the dynamics time
    # (docs/dynamics.md, iLQR refinement). Its cost also pulls the landmarks onto the
    # detections (image 3e3, root position 1e2 instead of 1e3; stop 40): MPJPE-PA and MPJPE-2d
    # about 2 mm and 2 px lower on motion capture, 2d lower on all three real videos and
    # walking_road's skate under 5 % (docs/dynamics.md, With the detections).
    # One retry, not two, and only attempts that could be kept refined (stop 41): in stop
    # 37-40's runs the second retry brought 9 of the 233 windows it was tried on within the
    # retry distance. The two real videos that retry took 0.62x and 0.48x the time at the same
    # figures; on motion capture MPJPE within 1 mm, foot skate 3.1 -> 4.2 % (+1.1 +- 0.8)
    # (docs/dynamics.md, Fewer attempts refined, one retry).
    # Retried whatever the first search's miss: not retrying after a miss beyond 0.5 m
    # (retry_within, stop 42) did 0.90x the rollouts on motion capture, but walking_road
    # restarted 9 times instead of 7 and its feet slid in 9.5 % of frames instead of 4.2 %,
    # over the 5 % bound, and the run's MPJPE-G rose 15 mm (docs/dynamics.md, Hopeless windows).
    # The start's depth speed as the reference has it (start_sight_smoothing 0): low-passed
    # over 0.25 s (stop 48) it lowered foot skate on the 7 real clips it was measured on
    # (4.1 -> 2.1 %, -1.9 +- 1.0 points), but raised motion capture's MPJPE-2d by 2.1 +- 1.1
    # px, and on three clips not in that measurement (two held-out segments and the demo) two
    # got worse (docs/dynamics.md, Start velocity along the line of sight).
    # A window also cut where the simulated head falls 0.15 m (reset_distance) below the
    # estimate's (fall_distance, stop 79): humanoid3d_roll's simulated body lay on the floor
    # four frames after the person got up (seed 0), the COM not yet 0.15 m off; on the 15
    # motion-capture clips under two seeds it changed three clips and no figure beyond its
    # noise, and the seven real clips not at all (docs/dynamics.md, Cuts).
    "fast": DynamicsConfig(tracking_start=True, weights=ObjectiveWeights(com=0.0, swing=12.0),
                           refine=RefineConfig(iterations=6, root_position=1e2, image=3e3),
                           retries=1, fall_distance=0.15),
    # The paper's budget: 2000 iterations x 100 samples per 1 s window, full covariance; its
    # reference is the grounded estimate as it is (no flattened stance feet).
    "paper": DynamicsConfig(popsize=100, iterations=2000, diagonal=False, search="all",
                            flat_stance=False),
}
# Table 2 (bottom half): objective terms removed.
ABLATIONS: dict[str, tuple[str, ...]] = {
    "no2d": ("reprojection",), "no3d": ("pose",), "nocom": ("com",),
    "nocompose": ("com", "pose"), "noprior": ("prior",),
}
# What the iLQR refinement's tracking cost asks for in the same role as each objective term,
# removed with it: the detections (the image term; the root held in depth needs its camera),
# the pose (root orientation and hinge angles, and the hinges' speeds) and the centre of mass
# (the root's place and velocity, which move the body's mass). The prior has no counterpart.
REFINE_COUNTERPARTS: dict[str, tuple[str, ...]] = {
    "reprojection": ("image", "root_depth"),
    "pose": ("root_orientation", "hinge", "hinge_velocity"),
    "com": ("root_position", "root_velocity", "root_depth"),
    "prior": (),
}


def ablated(config: DynamicsConfig, name: str) -> DynamicsConfig:
    """The config with the terms of ablation ``name`` (ABLATIONS) switched off, in the search's
    objective and, where the refinement is on, their counterparts in its tracking cost
    (REFINE_COUNTERPARTS): without them a refined ``no2d`` would still be pulled onto the
    detections."""
    expect_type(config, DynamicsConfig, "ablated's config", "pass e.g. PRESETS['fast']")
    if name not in ABLATIONS:
        raise PhysposeError(f"unknown ablation {name!r}", remedy=f"use one of {list(ABLATIONS)}")
    terms = ABLATIONS[name]
    weights = dataclasses.replace(config.weights, **{t: 0.0 for t in terms})
    refine = config.refine
    if refine.enabled:
        refine = dataclasses.replace(refine, **{w: 0.0 for t in terms
                                                for w in REFINE_COUNTERPARTS[t]})
    return dataclasses.replace(config, weights=weights, refine=refine)
