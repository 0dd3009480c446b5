"""backlashkit: simulate drive trains with gear backlash, identify the backlash from
measured speeds, and cancel it with adaptive backlash-inverse control.

Units are SI throughout. Every backlash figure called ``theta`` is the half-width of
the dead zone (the total gap is ``2 * theta``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .actuator import CurrentLoop
from .control import (
    AdaptiveLaw,
    DiscreteAdaptiveController,
    SumOfSines,
    TableReference,
    design_mrc,
    simulate_closed_loop,
)
from .encoder import Encoder, measure_encoders
from .errors import (
    CorrelatedResidualsWarning,
    InputError,
    NoiseLevelWarning,
    PriorMismatchWarning,
    SearchEdgeWarning,
    SensitivityWarning,
    StepDownWarning,
)
from .identify.crb import CramerRaoBound, cramer_rao_bound
from .identify.intervals import FisherInterval, ParametricBootstrap, ProfileLikelihood
from .identify.joint import JointIdentifier
from .identify.noise import ARNoise, AutoNoise, WhiteNoise
from .identify.readers import read_records, read_torque
from .identify.record import Record
from .identify.search import Continuation, FirstHorizon, JointSearch, Restarts, ThetaGrid
from .identify.torque import torque_levels
from .identify.two_step import RegressionIdentifier, TwoStepIdentifier
from .laws import ShaftLaw
from .lti import LinearPlantWithBacklash
from .nonlinearities import (
    Backlash,
    ExactInverse,
    GainOnlyInverse,
    NoInverse,
    SmoothFilterInverse,
    SmoothRampInverse,
)
from .plants import DriveChain, TwoMassDrive
from .simulate import (
    ContactEvent,
    DriveResponse,
    FrictionEvent,
    NearGrazing,
    Sensitivity,
    assess_sensitivity,
    simulate_batch,
    simulate_drive,
)

if TYPE_CHECKING:
    from .delay import DelayMarginResult, DelaySystem, delay_margin, read_delay_system

__version__ = "0.1.0"

#: Names of :mod:`backlashkit.delay` read from it on first use: it imports scipy, which
#: ``import backlashkit`` leaves out (about 0.9 s of a command's start).
_DELAY_NAMES = ("DelayMarginResult", "DelaySystem", "delay_margin", "read_delay_system")


def __getattr__(name: str) -> Any:
    if name in _DELAY_NAMES:
        from . import delay

        return getattr(delay, name)
    raise AttributeError(f"module 'backlashkit' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_DELAY_NAMES))


__all__ = [
    "ARNoise",
    "AutoNoise",
    "AdaptiveLaw",
    "Backlash",
    "DiscreteAdaptiveController",
    "ExactInverse",
    "GainOnlyInverse",
    "LinearPlantWithBacklash",
    "NoInverse",
    "ParametricBootstrap",
    "ProfileLikelihood",
    "Record",
    "RegressionIdentifier",
    "SmoothFilterInverse",
    "SmoothRampInverse",
    "SumOfSines",
    "TableReference",
    "design_mrc",
    "simulate_closed_loop",
    "ContactEvent",
    "CurrentLoop",
    "Encoder",
    "FrictionEvent",
    "measure_encoders",
    "CorrelatedResidualsWarning",
    "CramerRaoBound",
    "DelayMarginResult",
    "DelaySystem",
    "DriveChain",
    "DriveResponse",
    "FisherInterval",
    "InputError",
    "JointIdentifier",
    "JointSearch",
    "Restarts",
    "ThetaGrid",
    "FirstHorizon",
    "Continuation",
    "NearGrazing",
    "Sensitivity",
    "NoiseLevelWarning",
    "PriorMismatchWarning",
    "SearchEdgeWarning",
    "SensitivityWarning",
    "StepDownWarning",
    "ShaftLaw",
    "TwoMassDrive",
    "TwoStepIdentifier",
    "WhiteNoise",
    "__version__",
    "assess_sensitivity",
    "cramer_rao_bound",
    "delay_margin",
    "read_delay_system",
    "read_records",
    "read_torque",
    "simulate_batch",
    "simulate_drive",
    "torque_levels",
]
