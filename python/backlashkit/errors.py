"""Exceptions and warnings raised by backlashkit.

Every error caused by what the user gave (a parameter, a file, a signal) is an
:class:`InputError`, a subclass of :class:`ValueError`, whose message names what was
wrong, where, and what to do. The CLI prints that message on one line and exits with
status 2.

Where a message advises setting an option (``pass allow_far_from_prior=True``), the
advice is an :class:`Option` among the message's parts, so that a front end can word
it in its own terms (the command line says ``--allow-far-from-prior``):
:meth:`InputError.worded` joins the parts with each option spelled by the caller.
``str()`` of the error is the Python wording.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ["CorrelatedResidualsWarning", "Diagnostic", "InputError", "NoiseLevelWarning",
           "Option", "PriorMismatchWarning", "QuantisedSpeedsWarning", "SearchEdgeWarning",
           "SensitivityWarning", "StepDownWarning", "word_parts"]


@dataclass(frozen=True)
class Option:
    """An option that a message names or advises setting.

    Parameters
    ----------
    name : str
        The library parameter, e.g. ``"allow_far_from_prior"``.
    value : object, optional
        The value advised (default True: a switch to turn on); None when the message
        names the option without a value (``pass sample_time=``).
    python : str, optional
        How a Python caller writes the advice; default ``name=value!r`` (``name`` alone
        when ``value`` is None).
    """

    name: str
    value: Any = True
    python: str | None = None

    def __str__(self) -> str:
        if self.python is not None:
            return self.python
        return self.name if self.value is None else f"{self.name}={self.value!r}"


class Diagnostic:
    """A message made of text and :class:`Option` parts (mixed into the exceptions and
    warnings below).

    Parameters
    ----------
    *parts : str or Option
        The message, in order; ``str()`` joins them in Python's words.
    param : str, optional
        The library parameter the message is about, when it starts with its name (as
        validation messages do: ``final_horizon must be > 0, got -1``).
    """

    def __init__(self, *parts: str | Option, param: str | None = None) -> None:
        if param is not None and parts and isinstance(parts[0], str) \
                and parts[0].startswith(param):
            parts = (Option(param, None), parts[0][len(param):], *parts[1:])
        self.parts: tuple[str | Option, ...] = tuple(parts)
        self.param = param
        super().__init__("".join(str(p) for p in parts))

    def options(self) -> list[Option]:
        """The options the message names or advises, in order.

        Returns
        -------
        list of Option
            Every :class:`Option` among the parts.
        """
        return [p for p in self.parts if isinstance(p, Option)]

    def worded(self, spell: Callable[[Option], str | None]) -> str:
        """The message with every option spelled by ``spell``.

        Parameters
        ----------
        spell : callable
            ``spell(option)`` returns the front end's words for the option (a flag), or
            None to keep Python's.

        Returns
        -------
        str
            The message, one line.
        """
        return word_parts(self.parts, spell)

    def __reduce__(self):  # pickled (a worker process's error) with its parts
        return (_rebuild, (type(self), self.parts, self.param))


def word_parts(parts: Sequence[str | Option],
               spell: Callable[[Option], str | None] | None = None) -> str:
    """Message parts joined, every :class:`Option` spelled by ``spell``.

    Parameters
    ----------
    parts : sequence of str or Option
        The message.
    spell : callable, optional
        ``spell(option)`` returns a front end's words for the option, or None to keep
        Python's (default: Python's for all).

    Returns
    -------
    str
        The message.
    """
    words = []
    for part in parts:
        said = spell(part) if spell is not None and isinstance(part, Option) else None
        words.append(str(part) if said is None else said)
    return "".join(words)


def _rebuild(cls: type, parts: tuple, param: str | None) -> Diagnostic:
    out = cls.__new__(cls)
    Diagnostic.__init__(out, *parts)
    out.param = param
    return out


class InputError(Diagnostic, ValueError):
    """A parameter, signal or file given by the user is invalid.

    Parameters
    ----------
    *parts : str or Option
        The message (see :class:`Diagnostic`).
    param : str, optional
        The parameter the message is about, when it starts with its name.
    """


class SensitivityWarning(UserWarning):
    """A simulation passed close to a grazing contact.

    Near a grazing contact (the twist touches a backlash flank with almost zero
    relative speed) an arbitrarily small perturbation decides whether an impact
    happens, so the trajectory after it is ill-conditioned: any two accurate
    simulators may legitimately disagree there.
    """


class CorrelatedResidualsWarning(Diagnostic, UserWarning):
    """The residuals of a fit are correlated from sample to sample.

    The joint estimator's likelihood treats them as white (after whitening, with an
    autoregressive noise model); when they are not, its standard error and interval
    are too narrow.

    Parameters
    ----------
    *parts : str or Option
        The message (see :class:`Diagnostic`).
    param : str, optional
        The parameter the message is about, when it starts with its name.
    """


class PriorMismatchWarning(Diagnostic, UserWarning):
    """The data sit far from what the prior drive predicts.

    Emitted when a record's speeds under the torque held before the step-down are
    more than :data:`backlashkit.identify.FAR_FROM_PRIOR` times off the prior's
    response (the two-step and regression methods simulate the prior from them), or
    when a joint fit moves a linear parameter that far from the prior. Far more often
    than a prior that wrong, the speeds are in other units (rpm read as rad/s) or, for
    the joint fit, the speed columns are swapped; the estimate of ``theta`` then means
    nothing. Beyond :data:`backlashkit.identify.REFUSE_FROM_PRIOR` times the
    estimators refuse to answer unless ``allow_far_from_prior=True``. Also emitted
    where a joint fit pulls against a prior std (a prior-data conflict) or the data
    refute a known current loop's lag.

    Parameters
    ----------
    *parts : str or Option
        The message (see :class:`Diagnostic`).
    param : str, optional
        The parameter the message is about, when it starts with its name.
    """


class StepDownWarning(Diagnostic, UserWarning):
    """A record's torque steps down more than once.

    The methods locate the step-down as the largest drop of the torque; the others are
    only part of the record the model simulates. One step-down per record is the
    experiment the methods are made for: split such a record to use every step-down.

    Parameters
    ----------
    *parts : str or Option
        The message (see :class:`Diagnostic`).
    param : str, optional
        The parameter the message is about, when it starts with its name.
    """


class SearchEdgeWarning(Diagnostic, UserWarning):
    """An estimate sits at an end of its bounded search interval.

    The two-step and regression methods search ``theta`` in an interval; an estimate
    on its end says that the criterion's minimum may lie beyond it (for the two-step
    method: widen ``n_theta``).

    Parameters
    ----------
    *parts : str or Option
        The message (see :class:`Diagnostic`).
    param : str, optional
        The parameter the message is about, when it starts with its name.
    """


class NoiseLevelWarning(Diagnostic, UserWarning):
    """The noise levels given to a fit are far from its residuals' spread.

    The joint estimator weighs the residuals by the levels given (``noise=``) and
    takes its standard error and interval from them: a level off by a factor scales
    both by that factor.

    Parameters
    ----------
    *parts : str or Option
        The message (see :class:`Diagnostic`).
    param : str, optional
        The parameter the message is about, when it starts with its name.
    """


class QuantisedSpeedsWarning(Diagnostic, UserWarning):
    """A record's speeds are an encoder's differenced counts.

    Such a speed is the mean over the sample, not the speed at the sample, and its noise
    is the difference of two quantisation errors (lag-1 autocorrelation -0.5): the
    joint estimator's model has neither yet, so its ``theta`` may be biased by about a
    percent and its interval too narrow.

    Parameters
    ----------
    *parts : str or Option
        The message (see :class:`Diagnostic`).
    param : str, optional
        The parameter the message is about, when it starts with its name.
    """
