"""Exceptions raised by backlashkit.

Every error caused by what the user gave (a parameter, a file, a signal) is an
:class:`InputError`, a subclass of :class:`ValueError`, whose message names what was
wrong, where, and what to do. The CLI prints that message on one line and exits with
status 2.
"""

from __future__ import annotations

__all__ = ["CorrelatedResidualsWarning", "InputError", "SensitivityWarning"]


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
