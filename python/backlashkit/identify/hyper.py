"""The short ``repr`` of an estimator: its class and the hyperparameters it was given.

scikit-learn's convention: ``Name(prior, key=value, ...)`` with the prior first and only
the keyword options that differ from their defaults.
"""

from __future__ import annotations

import inspect
from typing import Any

__all__ = ["init_repr"]


def init_repr(estimator: Any) -> str:
    """``Name(first, key=value, ...)``: the first ``__init__`` argument, then each
    keyword option that is not its default.

    Parameters
    ----------
    estimator : object
        An object whose ``__init__`` arguments are kept as attributes of the same name.

    Returns
    -------
    str
        One line.
    """
    params = [p for name, p in inspect.signature(type(estimator).__init__).parameters.items()
              if name != "self"]
    first, *options = params
    args = [repr(getattr(estimator, first.name))] + [
        f"{p.name}={getattr(estimator, p.name)!r}" for p in options
        if not _same(getattr(estimator, p.name), p.default)]
    return f"{type(estimator).__name__}({', '.join(args)})"


def _same(value: Any, default: Any) -> bool:
    """Whether a hyperparameter is its default (anything incomparable differs)."""
    try:
        return bool(value is default or value == default)
    except (TypeError, ValueError):
        return False


def _learned_attribute(self: Any, name: str) -> Any:
    # An estimator's __getattr__, assigned in its class (a base class would lengthen
    # help()): a learned name (ending in "_") read before fit says to call fit, where
    # Python says only that it does not exist; fitted is when theta_ is set.
    if name.endswith("_") and not name.startswith("_") and "theta_" not in vars(self):
        raise AttributeError(f"{type(self).__name__}.{name} is learned by fit(): call "
                             "fit(records) first")
    raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
