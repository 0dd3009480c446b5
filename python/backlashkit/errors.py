"""Exceptions raised by backlashkit.

Every error caused by what the user gave (a parameter, a file, a signal) is an
:class:`InputError`, a subclass of :class:`ValueError`, whose message names what was
wrong, where, and what to do. The CLI prints that message on one line and exits with
status 2.
"""

from __future__ import annotations

__all__ = ["CorrelatedResidualsWarning", "InputError", "PriorMismatchWarning",
           "SensitivityWarning"]


class InputError(ValueError):
    """A parameter, signal or file given by the user is invalid."""


class SensitivityWarning(UserWarning):
    """A simulation passed close to a grazing contact.

    Near a grazing contact (the twist touches a backlash flank with almost zero
    relative speed) an arbitrarily small perturbation decides whether an impact
    happens, so the trajectory after it is ill-conditioned: any two accurate
    simulators may legitimately disagree there.
    """


class CorrelatedResidualsWarning(UserWarning):
    """The residuals of a fit are correlated from sample to sample.

    The joint estimator's likelihood treats them as white (after whitening, with an
    autoregressive noise model); when they are not, its standard error and interval
    are too narrow.
    """


class PriorMismatchWarning(UserWarning):
    """The data sit far from what the prior drive predicts.

    Emitted when a record's speeds under the torque held before the step-down are
    more than :data:`backlashkit.identify.FAR_FROM_PRIOR` times off the prior's
    response (the two-step and regression methods simulate the prior from them), or
    when a joint fit moves a linear parameter that far from the prior. Far more often
    than a prior that wrong, the speeds are in other units (rpm read as rad/s) or, for
    the joint fit, the speed columns are swapped; the estimate of ``theta`` then means
    nothing.
    """
