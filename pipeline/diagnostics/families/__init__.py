"""Effect families (diagnosis contract §2): one module per family, all registered here.

The registry is the one list of family ids: the config check, the contract check, the calibration
bench's menu and the report derive from it. Adding a family: a module with a :class:`Family` subclass
(see :mod:`.base`), its tests, and one line below.
"""

from __future__ import annotations

from .base import Context, Family, Hypothesis, Structure
from .coulomb_friction import CoulombFriction
from .cubic_stiffness import CubicStiffness
from .dead_zone import DeadZone
from .input_delay import InputDelay
from .input_saturation import InputSaturation
from .intersample import Intersample
from .noise_families import ColoredNoise, HeavyTailedNoise, HeteroscedasticNoise
from .offset import Offset
from .output_offset import OutputOffset
from .parameter_drift import ParameterDrift
from .parameter_jump import ParameterJump
from .periodic_disturbance import PeriodicDisturbance, amplitude_phase
from .quadratic_damping import QuadraticDamping
from .state_saturation import StateSaturation
from .static_nonlinearity import StaticNonlinearity
from .unmodeled_dynamics import UnmodeledDynamics

REGISTRY: dict[str, Family] = {f.id: f for f in (
    Intersample(), Offset(), OutputOffset(), CubicStiffness(), QuadraticDamping(), CoulombFriction(),
    StaticNonlinearity(), PeriodicDisturbance(), InputDelay(), InputSaturation(), DeadZone(), ParameterJump(),
    ParameterDrift(), UnmodeledDynamics(), StateSaturation(), ColoredNoise(), HeavyTailedNoise(),
    HeteroscedasticNoise())}

FAMILY_IDS: tuple[str, ...] = tuple(REGISTRY)
NOISE_FAMILY_IDS: tuple[str, ...] = tuple(k for k, f in REGISTRY.items() if f.stage == "noise")

__all__ = ["REGISTRY", "FAMILY_IDS", "NOISE_FAMILY_IDS", "Context", "Family", "Hypothesis", "Structure",
           "amplitude_phase"]
