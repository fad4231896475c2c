"""Finished steps of one kinematic fit, kept so that a fit stopped midway resumes after them.

On a clip of minutes each step of the fit (init, pose, temporal, ground plane, ground pose)
takes minutes. Each step's result (the parameters and the terms' values, or the plane) is
stored in the stage cache (`kinematics_steps`) under the fit's own cache key and the step's
name as soon as the step ends, so a fit stopped by Ctrl-C or a crash reads its finished steps
back on the next run and computes only the rest. The arrays come back bit for bit, and every
step starts from its predecessor's result alone, so the resumed fit is the one an unbroken run
gives. Once the whole fit is in the cache its steps are deleted.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable

import numpy as np

from physpose.cache import Cache
from physpose.kinematics.objective import Params

STAGE = "kinematics_steps"


class FitCheckpoints:
    """The finished steps of the fit whose cache key is `key`; with key None nothing is kept."""

    def __init__(self, key: str | None, log: Callable[[str], None] = lambda _: None):
        self.key, self.log = key, log
        self.cache = Cache(STAGE)
        self.kept: list[str] = []  # steps of this fit in the cache, written or read back

    def _entry(self, step: str) -> str:
        return hashlib.sha256(f"{self.key}/{step}".encode()).hexdigest()

    def params(self, step: str, compute: Callable[[], tuple[Params, dict]]
               ) -> tuple[Params, dict]:
        """The (parameters, terms' values) that step `step` gave, read back or computed."""
        arrays = self._read(step)
        if arrays is not None:
            losses = json.loads(str(arrays.pop("losses")))
            return Params(**{name: arrays[name] for name in Params._fields}), losses
        params, losses = compute()
        self._write(step, {name: np.asarray(value) for name, value in params._asdict().items()}
                    | {"losses": np.array(json.dumps(losses))})
        return params, losses

    def plane(self, step: str, compute: Callable[[], np.ndarray]) -> np.ndarray:
        """The ground plane (4,) that step `step` found, read back or computed."""
        arrays = self._read(step)
        if arrays is not None:
            return arrays["plane"]
        plane = np.asarray(compute(), dtype=float)
        self._write(step, {"plane": plane})
        return plane

    def clear(self) -> None:
        """Delete the kept steps (the whole fit is cached by now; with key None there are none)."""
        for step in self.kept:
            self.cache.path(self._entry(step)).unlink(missing_ok=True)

    def _read(self, step: str) -> dict[str, np.ndarray] | None:
        if self.key is None:
            return None
        arrays = self.cache.get(self._entry(step))
        if arrays is not None:
            self.kept.append(step)
            self.log(f"{step}: finished by an earlier run, read back")
        return arrays

    def _write(self, step: str, arrays: dict[str, np.ndarray]) -> None:
        if self.key is not None and self.cache.put(self._entry(step), arrays) is not None:
            self.kept.append(step)
