"""Backlash identification from step-down experiments.

One concept per module:

* :mod:`~backlashkit.identify.record` -- :class:`Record` and the checks that refuse an
  unusable record (library and command line alike);
* :mod:`~backlashkit.identify.readers` -- measured files (CSV, ``.mat``, ``.npz``) to
  Records;
* :mod:`~backlashkit.identify.step` -- the torque step-down and the speed held before it;
* :mod:`~backlashkit.identify.torque` -- a measured torque's noise and its levels;
* :mod:`~backlashkit.identify.commutation` -- the contact changes after a step-down
  and paper A's pre-estimate;
* :mod:`~backlashkit.identify.two_step`, :mod:`~backlashkit.identify.decay` -- paper
  A's two-step method and its regression baseline, and their free-decay model;
* :mod:`~backlashkit.identify.joint` -- the joint maximum-likelihood estimator;
* :mod:`~backlashkit.identify.search`, :mod:`~backlashkit.identify.intervals`,
  :mod:`~backlashkit.identify.noise` -- its search, interval and noise models;
* :mod:`~backlashkit.identify.terms` -- the Coulomb friction and current loop it adds
  where the records show them;
* :mod:`~backlashkit.identify.crb` -- the Cramér-Rao bound;
* :mod:`~backlashkit.identify.plots`, :mod:`~backlashkit.identify.report` -- its figures
  and the HTML identification report.

Every ``theta`` is the backlash **half-width** in rad; units are SI.
"""

from __future__ import annotations

from .commutation import Commutation, commutation_instants, fir_lowpass, pre_estimate
from .crb import CramerRaoBound, cramer_rao_bound
from .intervals import FisherInterval, ParametricBootstrap, ProfileLikelihood
from .joint import LINEAR_PARAMS, JointIdentifier
from .noise import ARNoise, AutoNoise, WhiteNoise
from .readers import read_records, read_torque
from .record import Record, as_records
from .search import Continuation, FirstHorizon, JointSearch, Restarts, ThetaGrid
from .step import (
    FAR_FROM_PRIOR,
    REFUSE_FROM_PRIOR,
    check_fit_near_prior,
    check_held_speeds,
    check_held_steady,
    check_step_downs,
    find_step_down,
    held_speed_gain,
    held_unsteady_share,
    is_far,
)
from .terms import KEEP_LEVEL, TermChoice
from .torque import torque_levels
from .two_step import RegressionIdentifier, TwoStepIdentifier

__all__ = [
    "ARNoise",
    "AutoNoise",
    "Commutation",
    "CramerRaoBound",
    "FAR_FROM_PRIOR",
    "FisherInterval",
    "JointIdentifier",
    "JointSearch",
    "KEEP_LEVEL",
    "Restarts",
    "ThetaGrid",
    "FirstHorizon",
    "Continuation",
    "LINEAR_PARAMS",
    "ParametricBootstrap",
    "ProfileLikelihood",
    "REFUSE_FROM_PRIOR",
    "Record",
    "RegressionIdentifier",
    "TermChoice",
    "TwoStepIdentifier",
    "WhiteNoise",
    "as_records",
    "check_fit_near_prior",
    "check_held_speeds",
    "check_held_steady",
    "check_step_downs",
    "commutation_instants",
    "cramer_rao_bound",
    "find_step_down",
    "fir_lowpass",
    "held_speed_gain",
    "held_unsteady_share",
    "is_far",
    "pre_estimate",
    "read_records",
    "read_torque",
    "torque_levels",
]
