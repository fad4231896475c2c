"""Temporal windows: where each window starts and ends, and one window's search problem.

Times live on the simulation's step grid (step n at n * dt seconds); frame j is at j / fps,
i.e. at fractional step position j / (fps dt). A window spans frames [first, last]; its
simulation starts at the step at or just before its first frame and runs to the step at or just
after its last one.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from physpose.dynamics.balance import BalancePlan
from physpose.dynamics.objective import (ObjectiveReference, ObjectiveWeights, evaluate_terms,
                                         invalid_from, total)
from physpose.dynamics.rollout import FrameSamples, Trajectories


@dataclass(frozen=True)
class Window:
    """Frames [first, last] (inclusive) simulated over steps [start_step, end_step]."""

    index: int
    first: int
    last: int
    start_step: int
    end_step: int

    @property
    def num_steps(self) -> int:
        return self.end_step - self.start_step

    @property
    def frames(self) -> np.ndarray:
        return np.arange(self.first, self.last + 1)


def step_position(frame: np.ndarray | int, fps: float, dt: float) -> np.ndarray:
    """Fractional simulation step of frame(s)."""
    return np.asarray(frame, dtype=float) / (fps * dt)


def plan_windows(num_frames: int, fps: float, dt: float, window: float, overlap: float,
                 anchor_last: bool = False, min_span: float = 0.0) -> list[Window]:
    """Overlapping windows of ``window`` s sharing ``overlap`` s, covering every frame.

    The last window ends on the last frame; with ``anchor_last`` it also keeps the full
    length (starting earlier, so it may overlap its predecessor more). No window spans less
    than ``min_span`` s (the clip allowing): a last window that would is merged into the one
    before it. (A sequential window searches the spline coefficients that begin inside it;
    one shorter than the knot spacing can lie between two knots and have none.)
    """
    span = int(math.ceil(min_span * fps - 1e-9))
    length = max(2, int(round(window * fps)), span)
    shared = min(max(0, int(round(overlap * fps))), length - 1)
    stride = length - shared
    last_frame = num_frames - 1
    starts = [0]
    while starts[-1] + length < last_frame:
        starts.append(starts[-1] + stride)
    if not anchor_last and len(starts) > 1 and last_frame - starts[-1] < span:
        starts.pop()  # (an anchored last window keeps the full length: nothing to merge)
    if anchor_last and len(starts) > 1:
        starts[-1] = max(0, last_frame - length)
    ends = [min(first + length, last_frame) for first in starts[:-1]] + [last_frame]
    return [window_over(i, first, last, fps, dt)
            for i, (first, last) in enumerate(zip(starts, ends))]


def window_over(index: int, first: int, last: int, fps: float, dt: float) -> Window:
    """The window of frames [first, last]: its simulation starts at the step at or just
    before ``first`` and ends at the step at or just after ``last``."""
    return Window(index=index, first=first, last=last,
                  start_step=int(math.floor(step_position(first, fps, dt) + 1e-9)),
                  end_step=int(math.ceil(step_position(last, fps, dt) - 1e-9)))


@dataclass(frozen=True, eq=False)
class WindowProblem:
    """One window's search: ctrl = fixed_ctrl + basis @ x for x (nfree, 48), from state0.

    free: which of the clip's spline coefficients x stands for. basis (S, nfree): the free coefficients' spline basis at the window's steps;
    fixed_ctrl (S, 48): the contribution of every other coefficient; x0 (nfree, 48) start.
    positions (F,): the frames' step positions relative to start_step. history (H, 21, 3).
    """

    window: Window
    state0: np.ndarray
    free: slice
    dofs: np.ndarray
    basis: np.ndarray
    fixed_ctrl: np.ndarray
    start: np.ndarray
    positions: np.ndarray
    history: np.ndarray | None
    alternatives: tuple[np.ndarray, ...] = ()  # other start guesses: servo targets (S, 48)
    balance: BalancePlan | None = None  # closed-loop balance feedback in its rollouts

    @property
    def x0(self) -> np.ndarray:
        return self.start[:, self.dofs]

    def coefficients(self, x: np.ndarray) -> np.ndarray:
        """Free coefficients (B, nfree, 48) for flat search vectors x (B, nfree * ndofs)."""
        x = np.asarray(x, dtype=float).reshape(len(x), len(self.start), len(self.dofs))
        coefs = np.repeat(self.start[None], len(x), axis=0)
        coefs[:, :, self.dofs] = x
        return coefs

    def ctrl(self, x: np.ndarray) -> np.ndarray:
        """Servo targets (B, S, 48) for flat search vectors x (B, nfree * ndofs)."""
        return self.fixed_ctrl + np.matmul(self.basis, self.coefficients(x))

    def starting_from(self, ctrl: np.ndarray) -> WindowProblem:
        """The same search with its start x0 giving exactly the servo targets ctrl (S, 48):
        the search then varies spline offsets on top of them."""
        shift = np.asarray(ctrl, dtype=float) - self.ctrl(self.x0.reshape(1, -1))[0]
        return dataclasses.replace(self, fixed_ctrl=self.fixed_ctrl + shift, alternatives=())


@dataclass(frozen=True, eq=False)
class Scores:
    """A batch's objective: terms (B,) per name, total (B,) (+inf when invalid), first bad frame."""

    terms: dict[str, np.ndarray]
    total: np.ndarray
    invalid_from: np.ndarray


def score(problem: WindowProblem, traj: Trajectories, ref: ObjectiveReference,
          weights: ObjectiveWeights, max_root_distance: float, max_penetration: float
          ) -> tuple[Scores, FrameSamples]:
    """Sample a batch's trajectories at the window's frames and evaluate the objective."""
    samples = traj.at(problem.positions)
    frames = problem.window.frames
    terms = evaluate_terms(samples, ref, frames, problem.history, weights)
    bad = invalid_from(samples, ref, frames, max_root_distance, max_penetration)
    value = total(terms, weights)
    value = np.where((bad < len(frames)) | ~np.isfinite(value), np.inf, value)
    return Scores(terms=terms, total=value, invalid_from=bad), samples


def ranked_fitness(scores: Scores, num_frames: int) -> np.ndarray:
    """Finite fitness for CMA-ES: invalid samples rank below every valid one, and among
    themselves by how early they failed."""
    value = scores.total.copy()
    valid = np.isfinite(value)
    worst = max(1e6, 10.0 * float(np.max(np.abs(value[valid])))) if valid.any() else 1e6
    value[~valid] = worst + (num_frames - scores.invalid_from[~valid])
    return value


def blend_weights(windows: list[Window], num_frames: int) -> np.ndarray:
    """(W, T) weights joining independently optimised windows, each frame's summing to 1.

    The windows are joined in order: each fades in linearly over its overlap with the frames
    the windows before it cover, and the join so far fades out by the same ramp. Where two
    windows overlap this is the plain linear cross-fade; where a window (an anchored last
    one) reaches over two or more, it fades into their join instead of into one of them.
    """
    w = np.zeros((len(windows), num_frames))
    covered = -1
    for i, win in enumerate(windows):
        ramp = np.ones(win.last - win.first + 1)
        n = min(covered, win.last) - win.first + 1
        if n > 0:
            ramp[:n] = (np.arange(n) + 1.0) / (n + 1.0)
            w[:i, win.first:win.first + n] *= 1.0 - ramp[:n]
        w[i, win.first:win.last + 1] = ramp
        covered = max(covered, win.last)
    return w
