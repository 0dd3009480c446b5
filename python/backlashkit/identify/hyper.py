"""An estimator's hyperparameters: its short ``repr``, ``get_params`` and ``set_params``.

scikit-learn's conventions: ``Name(prior, key=value, ...)`` with the prior first and
only the keyword options that differ from their defaults; the ``__init__`` arguments
read and set by name (so that ``sklearn.base.clone`` and its searches work). The
estimators take the two methods as class attributes, not from a base class (which
would lengthen their ``help()``).
"""

from __future__ import annotations

import difflib
import inspect
from typing import Any

from ..errors import InputError

__all__ = ["get_params", "init_repr", "set_params"]


def _init_names(cls: type) -> list[str]:
    """The names of ``cls.__init__``'s arguments, ``self`` left out."""
    return [n for n in inspect.signature(cls.__init__).parameters if n != "self"]


def get_params(self: Any, deep: bool = True) -> dict[str, Any]:
    """The estimator's hyperparameters: its ``__init__`` arguments by name.

    Parameters
    ----------
    deep : bool, optional
        Accepted for scikit-learn's protocol; the values are returned as they are
        (configuration objects are immutable).

    Returns
    -------
    dict of str to object
        Each ``__init__`` argument's current value.
    """
    return {name: getattr(self, name) for name in _init_names(type(self))}


def set_params(self: Any, **params: Any) -> Any:
    """Set hyperparameters by name; checked, as the others, when ``fit`` runs.

    Parameters
    ----------
    **params : object
        New values of ``__init__`` arguments.

    Returns
    -------
    object
        The estimator itself.

    Raises
    ------
    InputError
        If a name is not an ``__init__`` argument.
    """
    names = _init_names(type(self))
    for name, value in params.items():
        if name not in names:
            close = difflib.get_close_matches(name, names, n=1)
            meant = f" (did you mean {close[0]!r}?)" if close else ""
            raise InputError(f"{type(self).__name__} has no hyperparameter {name!r}{meant}; "
                             f"it has {', '.join(names)}")
        setattr(self, name, value)
    return self


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
