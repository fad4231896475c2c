"""Batched, multithreaded simulation of the body under open-loop servo targets.

`mujoco.rollout` steps many samples from their initial states on a thread pool. The body's
model gets sensors for what the objective reads at the frame times: the world positions of the
33 landmark sites and the 21 project joints (framepos) and the whole-body centre of mass
(subtreecom of the pelvis). After ``mj_step``, sensordata describes the state *before* the step,
so a rollout of n + 1 steps yields the sensors of states 0..n; states are sampled at the frame
times by linear interpolation between the two neighbouring simulation steps.

A sample is broken from the first step at which MuJoCo raised a warning (rollout then freezes
it, so its clock stops: checked on the state's time) or produced a non-finite number.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from mujoco import rollout as mj_rollout

from physpose.body import Body
from physpose.dynamics import quat
from physpose.dynamics.balance import BalancePlan
from physpose.dynamics.init import step_interpolation
from physpose.joints import JOINT_NAMES, LANDMARK_NAMES
from physpose.skeleton import NQ, NUM_DOF, NV

_FULL = mujoco.mjtState.mjSTATE_FULLPHYSICS
_SITE = mujoco.mjtObj.mjOBJ_SITE
_TIME_TOLERANCE = 1e-7  # s, clock mismatch that marks a frozen (warned) sample


@dataclass(frozen=True, eq=False)
class SimModel:
    """The body's MuJoCo model with the sensors the objective reads.

    nstate: length of a FULLPHYSICS state ([time, qpos (55), qvel (54), ...]). dt: s per step.
    """

    body: Body
    model: mujoco.MjModel
    nstate: int
    dt: float

    @property
    def qpos_slice(self) -> slice:
        return slice(1, 1 + NQ)

    @property
    def qvel_slice(self) -> slice:
        return slice(1 + NQ, 1 + NQ + NV)


_NUM_LANDMARK_VALUES = 3 * len(LANDMARK_NAMES)
_NUM_JOINT_VALUES = 3 * len(JOINT_NAMES)


def sim_model(body: Body) -> SimModel:
    """Copy the body's spec, add the landmark/joint/COM sensors, compile."""
    spec = body.spec.copy()
    for name in (*LANDMARK_NAMES, *JOINT_NAMES):
        spec.add_sensor(name=f"pos_{name}", type=mujoco.mjtSensor.mjSENS_FRAMEPOS,
                        objtype=_SITE, objname=name)
    spec.add_sensor(name="com", type=mujoco.mjtSensor.mjSENS_SUBTREECOM,
                    objtype=mujoco.mjtObj.mjOBJ_BODY, objname="pelvis")
    model = spec.compile()
    assert model.nsensordata == _NUM_LANDMARK_VALUES + _NUM_JOINT_VALUES + 3
    return SimModel(body=body, model=model, nstate=mujoco.mj_stateSize(model, _FULL),
                    dt=float(model.opt.timestep))


def make_state(sim: SimModel, qpos: np.ndarray, qvel: np.ndarray, time: float = 0.0
               ) -> np.ndarray:
    """A FULLPHYSICS state (nstate,) from qpos (55,), qvel (54,) and the clock (s)."""
    data = mujoco.MjData(sim.model)
    data.qpos[:] = qpos
    data.qvel[:] = qvel
    data.time = time
    out = np.empty(sim.nstate)
    mujoco.mj_getState(sim.model, data, out, _FULL)
    return out


@dataclass(frozen=True, eq=False)
class FrameSamples:
    """Rollout outputs at the frame times of a window.

    qpos (B, F, 55) (root quaternion renormalised), landmarks (B, F, 33, 3), joints
    (B, F, 21, 3), com (B, F, 3), metres. broken (B, F) bool: the sample had failed by then.
    """

    qpos: np.ndarray
    landmarks: np.ndarray
    joints: np.ndarray
    com: np.ndarray
    broken: np.ndarray


@dataclass(frozen=True, eq=False)
class Trajectories:
    """Every step of a batch: states (B, n+1, nstate), sensors (B, n+1, nsens), broken (B, n+1).

    ctrl (B, n, 48): the servo targets applied (the given ones plus any balance feedback), or
    None when not recorded.
    """

    states: np.ndarray
    sensors: np.ndarray
    broken: np.ndarray
    ctrl: np.ndarray | None = None

    def at(self, positions: np.ndarray) -> FrameSamples:
        """Sample at fractional step positions (F,) in [0, n] by linear interpolation."""
        i0, i1, w = step_interpolation(positions, self.states.shape[1] - 1)
        w = w[None, :, None]

        def lerp(a: np.ndarray) -> np.ndarray:
            return (1.0 - w) * a[:, i0] + w * a[:, i1]

        qpos = lerp(self.states[..., 1:1 + NQ])
        qpos[..., 3:7] = quat.normalised(qpos[..., 3:7])
        sens = lerp(self.sensors)
        b, f = sens.shape[:2]
        lm = sens[..., :_NUM_LANDMARK_VALUES].reshape(b, f, len(LANDMARK_NAMES), 3)
        jt = sens[..., _NUM_LANDMARK_VALUES:_NUM_LANDMARK_VALUES + _NUM_JOINT_VALUES]
        com = sens[..., -3:]
        broken = self.broken[:, i1] | self.broken[:, i0]
        return FrameSamples(qpos=qpos, landmarks=lm, joints=jt.reshape(b, f, len(JOINT_NAMES), 3),
                            com=com, broken=broken)


class Simulator:
    """A thread pool and per-thread MjData for repeated batched rollouts of one model."""

    def __init__(self, sim: SimModel, nthread: int = 2):
        self.sim = sim
        self.nthread = max(1, int(nthread))
        self._pool = mj_rollout.Rollout(nthread=self.nthread if self.nthread > 1 else 0)
        self._data = [mujoco.MjData(sim.model) for _ in range(self.nthread)]

    def close(self) -> None:
        self._pool.close()

    def __enter__(self) -> Simulator:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def run(self, state0: np.ndarray, ctrl: np.ndarray,
            feedback: list[tuple[slice, BalancePlan]] | None = None) -> Trajectories:
        """Roll out servo targets ctrl (B, n, 48) from state0 (nstate,) or (B, nstate).

        feedback: balance plans and the rows they steer; the batch is then stepped in chunks
        between the plans' feedback steps, each chunk's targets offset by the feedback on the
        samples' COM at its start. Returns states and sensors of the n + 1 states 0..n
        (state 0 = state0) and the targets applied.
        """
        ctrl = np.asarray(ctrl, dtype=float)
        b, n, nu = ctrl.shape
        assert nu == NUM_DOF, ctrl.shape
        state0 = np.atleast_2d(np.asarray(state0, dtype=float))
        state0 = np.broadcast_to(state0, (b, self.sim.nstate)).copy()
        # One extra step: its sensors are those of state n (sensors lag the state by a step).
        padded = np.concatenate([ctrl, ctrl[:, -1:]], axis=1)
        if feedback:
            states, sensors, padded = self._run_with_feedback(state0, padded, feedback)
        else:
            states, sensors = self._pool.rollout(self.sim.model, self._data, state0, padded)
        states = np.concatenate([state0[:, None], states[:, :n]], axis=1)
        expected = state0[:, :1] + self.sim.dt * np.arange(n + 1)[None, :]
        bad = (np.abs(states[..., 0] - expected) > _TIME_TOLERANCE) \
            | ~np.isfinite(states).all(axis=-1) | ~np.isfinite(sensors).all(axis=-1)
        broken = np.logical_or.accumulate(bad, axis=1)
        return Trajectories(states=states, sensors=sensors, broken=broken, ctrl=padded[:, :n])

    def _run_with_feedback(self, state0: np.ndarray, padded: np.ndarray,
                           feedback: list[tuple[slice, BalancePlan]]
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Chunked rollout; the first chunk runs without feedback (no sensors yet), later
        ones read the COM of the chunk's last sensed state (one step old) and its velocity
        over the chunk."""
        applied = padded.copy()
        total = padded.shape[1]
        bounds = sorted({int(s) for _, plan in feedback for s in plan.starts if 0 < s < total})
        bounds = [0, *bounds, total]
        states, sensors = [], []
        current = state0
        for a, z in zip(bounds[:-1], bounds[1:]):
            if a > 0:
                com = sensors[-1][:, -1, -3:]
                span = sensors[-1].shape[1] - 1
                vel = (com - sensors[-1][:, 0, -3:]) / (span * self.sim.dt) if span > 0 \
                    else np.zeros_like(com)
                for rows, plan in feedback:
                    chunk = int(np.searchsorted(plan.starts, a, side="right")) - 1
                    if plan.starts[chunk] != a:
                        continue  # this plan has no feedback step here; keeps its offset
                    offset = plan.offsets(chunk, com[rows], vel[rows])
                    applied[rows, a:] = padded[rows, a:] + offset[:, None, :]
            st, se = self._pool.rollout(self.sim.model, self._data, current,
                                        np.ascontiguousarray(applied[:, a:z]))
            states.append(st)
            sensors.append(se)
            current = st[:, -1].copy()
        return np.concatenate(states, axis=1), np.concatenate(sensors, axis=1), applied
