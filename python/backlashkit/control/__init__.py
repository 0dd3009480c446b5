"""Adaptive backlash-inverse control of a known linear plant (Tao & Kokotović 1995).

* :func:`design_mrc` -- model-reference design, Diophantine equation (3.3), A1-A2 checks;
* :class:`AdaptiveLaw` -- gains of the adaptive law (3.11);
* :func:`simulate_closed_loop` -- continuous-time closed loop (compiled kernel);
* :class:`DiscreteAdaptiveController` -- the controller sample by sample (``v = ctrl.step(y, r)``);
* :func:`load_scenario` -- TOML scenario files of ``backlashkit control``.

Note: inside this subpackage ``control`` is *this* package; python-control is never
imported here.
"""

from __future__ import annotations

from .adaptive import AdaptiveLaw
from .closed_loop import (
    ClosedLoopResponse,
    SumOfSines,
    TableReference,
    simulate_closed_loop,
)
from .design import MRCDesign, design_mrc
from .discrete import DiscreteAdaptiveController, simulate_discrete_loop
from .scenario import ControlScenario, load_scenario

__all__ = [
    "AdaptiveLaw",
    "ClosedLoopResponse",
    "ControlScenario",
    "DiscreteAdaptiveController",
    "MRCDesign",
    "SumOfSines",
    "TableReference",
    "design_mrc",
    "load_scenario",
    "simulate_closed_loop",
    "simulate_discrete_loop",
]
