"""The kinematic stage: shape, camera, ground plane and per-frame pose (HUND+SO+GT analogue).

    fit = fit_kinematics(observations, KinematicConfig.preset("SO+GT"), height=1.75)

See docs/kinematics.md.
"""

from physpose.kinematics.config import VARIANT_NAMES, KinematicConfig
from physpose.kinematics.fit import fit_kinematics, fit_variants
from physpose.kinematics.result import KinematicFit

__all__ = ["KinematicFit", "KinematicConfig", "VARIANT_NAMES", "fit_kinematics", "fit_variants"]
