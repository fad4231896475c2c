"""The dynamics stage: physics-based trajectory optimisation (paper sec. 3.2-3.3).

Public API: `optimize_dynamics`, `DynamicsConfig`, `PRESETS`, `ABLATIONS`, `ablated`,
`PhysicsResult`, `ObjectiveWeights`. See docs/dynamics.md.
"""

from physpose.dynamics.objective import TERMS, ObjectiveWeights
from physpose.dynamics.config import ABLATIONS, PRESETS, DynamicsConfig, ablated
from physpose.dynamics.optimize import optimize_dynamics
from physpose.dynamics.result import PhysicsResult

__all__ = ["optimize_dynamics", "DynamicsConfig", "PRESETS", "ABLATIONS", "ablated",
           "PhysicsResult", "ObjectiveWeights", "TERMS"]
