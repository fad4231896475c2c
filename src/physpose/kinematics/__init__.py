"""The kinematic stage: shape, camera, ground plane and per-frame pose (HUND+SO+GT analogue)."""

from physpose.kinematics.result import KinematicFit

__all__ = ["KinematicFit"]
