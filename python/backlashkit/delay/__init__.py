"""How much delay a linear system tolerates: maximal delay intervals (Chen, IEEE TAC 1995).

For ``x'(t) - sum_k B_k x'(t - k h) = A0 x(t) + sum_k A_k x(t - k h)``, ``k = 1..q``:

* :func:`delay_margin` -- ``h_max`` with ``[0, h_max)`` the largest stable delay
  interval, by Chen's frequency sweep (``method="sweep"``) or the Kronecker-sum pencil
  of Chen, Gu & Nett 1995 (``method="kronecker"``); returns a
  :class:`DelayMarginResult` (``h_max``, ``omega``, ``vector``, ``stable_at_zero``,
  ``delay_independent``, ``stability_windows``, ``plot``);
* :class:`DelaySystem` -- the validated matrices; :func:`read_delay_system` reads the
  ``[delay_system]`` table of a TOML file;
* :func:`rightmost_root`, :func:`spectral_margin` -- the independent check: the
  rightmost characteristic roots by Chebyshev collocation of the infinitesimal
  generator (Breda, Maset & Vermiglio 2005).

Delays in seconds, frequencies in rad/s.
"""

from __future__ import annotations

from .margin import delay_margin, margin_of_system
from .result import DelayMarginResult
from .spectral import rightmost_root, spectral_margin, spectral_roots
from .system import DelaySystem, read_delay_system

__all__ = [
    "DelayMarginResult",
    "DelaySystem",
    "delay_margin",
    "margin_of_system",
    "read_delay_system",
    "rightmost_root",
    "spectral_margin",
    "spectral_roots",
]
