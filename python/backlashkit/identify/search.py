"""How the joint estimator searches: its configuration objects.

``JointIdentifier(prior, search=JointSearch(...))``. The defaults are the tested
search; each field says what it changes. The stages run in this order
(:mod:`backlashkit.identify._search` holds them; ``docs/design/joint-search.md`` says
why each exists):

1. :class:`ThetaGrid` -- a grid of ``theta`` (and optionally ``k_sh``) with the linear
   parameters at the prior, simulated as one batch; its best local minima and paper
   A's two-step estimate are the starts.
2. :class:`FirstHorizon` -- every start refined on a short window after the start of
   each record and after every torque jump, within a box around the prior, and the
   best one restarted from other splits of ``J_M + J_L`` and ``f_M + f_L``.
3. :class:`Continuation` -- the best distinct solutions continued on growing windows,
   then refined on the whole record (or ``final_horizon``).
4. :class:`Restarts` -- the best solution restarted from the prior's point, with the
   stiffness (screened on a short and on a longer window) and the friction split
   shifted, and the whole search run again from a fit that misfits.

Then the noise levels are re-estimated from the residuals (``noise_iter`` times) and
the uncertainty computed. Every object is frozen and validated on construction; a
message names the field (qualified by its class for the parts of the search), the
constraint and the value.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field, fields

import numpy as np

from .. import validate as v
from ..errors import InputError

__all__ = ["Continuation", "FirstHorizon", "JointSearch", "Restarts", "ThetaGrid"]

#: Default upper end of the theta grid: a 15 deg half-width, 7.5 times paper A's 2 deg;
#: a larger backlash needs a larger ``ThetaGrid(theta_max=...)``.
THETA_MAX = float(np.deg2rad(15.0))
#: ``Restarts.no_backlash`` starts ``theta`` at this share of the solution's: from a
#: solution at the first window's lower bound (``theta_max / 1000``, 2.6e-4 rad) that is
#: 2.6e-7 rad, below the median standard errors near 0 of both drives of
#: ``benchmarks/small_backlash.py`` (8.9e-6 and 2.8e-6 rad), so the restart starts in
#: the basin of no backlash wherever the search ended above it.
NO_BACKLASH_SHARE = 1e-3


def _shifts(owner: str, name: str, value) -> tuple[float, ...]:
    """``value`` as a tuple of finite numbers > 0, or an error naming ``owner.name``."""
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
        raise InputError(f"{owner}.{name} must be a sequence of numbers > 0, got {value!r}")
    return tuple(v.positive(f"{owner}.{name}[{i}]", x) for i, x in enumerate(value))


def _flag(owner: str, name: str, value) -> bool:
    return v.flag(f"{owner}.{name}", value)


def _factor(owner: str, name: str, value) -> float:
    """A factor: a finite number > 1."""
    x = v.positive(f"{owner}.{name}", value)
    if not x > 1.0:
        raise InputError(f"{owner}.{name} must be > 1 (a factor), got {value!r}")
    return x


class _Config:
    """Frozen dataclass helpers: a short repr (fields that differ from the default)."""

    def __repr__(self) -> str:
        changed = []
        for f in fields(self):  # type: ignore[arg-type]
            default = f.default_factory() if callable(f.default_factory) else f.default
            value = getattr(self, f.name)
            if value != default:
                changed.append(f"{f.name}={value!r}")
        return f"{type(self).__name__}({', '.join(changed)})"

    def _set(self, name: str, value) -> None:
        object.__setattr__(self, name, value)


@dataclass(frozen=True, repr=False)
class ThetaGrid(_Config):
    """The initial grid: where the starts of the search come from.

    Parameters
    ----------
    theta_max : float, optional
        Upper end of the grid in rad (default 15 deg); the grid is ``points`` values
        over ``(0, theta_max]``.
    points : int, optional
        Values of ``theta`` (default 61: steps of 0.25 deg over the default range).
    starts : int, optional
        Best local minima of the grid refined (default 3).
    two_step_start : bool, optional
        Also start from paper A's two-step estimate when it succeeds (default True).
    stiffness_points : int, optional
        Values of ``k_sh`` per ``theta``, geometric over ``k_prior * [1 /
        stiffness_span, stiffness_span]`` (default 1: the prior's only; more cost a
        batch each and did not remove the failures they moved).
    stiffness_span : float, optional
        Largest factor between a gridded and the prior ``k_sh``, > 1 (default 1.6).
    """

    theta_max: float = THETA_MAX
    points: int = 61
    starts: int = 3
    two_step_start: bool = True
    stiffness_points: int = 1
    stiffness_span: float = 1.6

    def __post_init__(self) -> None:
        self._set("theta_max", v.positive("ThetaGrid.theta_max", self.theta_max))
        note = v.degrees_note("ThetaGrid.theta_max", self.theta_max)
        if note is not None:
            warnings.warn(note, UserWarning, stacklevel=3)
        v.integer("ThetaGrid.points", self.points, 2)
        v.integer("ThetaGrid.starts", self.starts, 1)
        self._set("two_step_start", _flag("ThetaGrid", "two_step_start", self.two_step_start))
        v.integer("ThetaGrid.stiffness_points", self.stiffness_points, 1)
        self._set("stiffness_span", _factor("ThetaGrid", "stiffness_span",
                                            self.stiffness_span))

    @property
    def bounds(self) -> tuple[float, float]:
        """Smallest and largest ``theta`` of the grid in rad."""
        return (self.theta_max / self.points, self.theta_max)

    def thetas(self) -> np.ndarray:
        """The grid of ``theta`` in rad.

        Returns
        -------
        numpy.ndarray
            ``points`` values, evenly spaced over ``(0, theta_max]``.
        """
        return np.linspace(self.theta_max / self.points, self.theta_max, self.points)

    def stiffness_scales(self) -> Sequence[float]:
        """Factors of the prior's ``k_sh`` gridded with every ``theta``.

        Returns
        -------
        sequence of float
            ``[1.0]``, or ``stiffness_points`` geometric values over
            ``[1 / stiffness_span, stiffness_span]``.
        """
        if self.stiffness_points == 1:
            return [1.0]
        return np.geomspace(1.0 / self.stiffness_span, self.stiffness_span,
                            self.stiffness_points)


@dataclass(frozen=True, repr=False)
class FirstHorizon(_Config):
    """The refinement of every start on a short window.

    Parameters
    ----------
    horizon : float, optional
        Window in s after the start of each record and after every torque jump
        (default 0.15: about three periods of paper A's ringing, before its phase
        drifts into neighbouring basins).
    max_iter : int, optional
        Levenberg-Marquardt iterations per start (default 10).
    search_factor : float or None, optional
        Every linear parameter stays within this factor of the prior and ``theta``
        within ``[theta_max / 1000, theta_max]`` (default 3: a short noisy window
        is fitted as well by a far softer shaft without backlash); None: unbounded.
    split_shifts : sequence of float, optional
        The best solution is also restarted with ``J_M / J_L`` and ``f_M / f_L``
        multiplied by ``e^-x`` and ``e^x`` for every ``x`` (sums and ringing frequency
        kept: the window pins those, not the splits); default ``(0.5,)``.
    """

    horizon: float = 0.15
    max_iter: int = 10
    search_factor: float | None = 3.0
    split_shifts: Sequence[float] = (0.5,)

    def __post_init__(self) -> None:
        self._set("horizon", v.positive("FirstHorizon.horizon", self.horizon))
        v.integer("FirstHorizon.max_iter", self.max_iter, 1)
        if self.search_factor is not None:
            self._set("search_factor", _factor("FirstHorizon", "search_factor",
                                               self.search_factor))
        self._set("split_shifts", _shifts("FirstHorizon", "split_shifts", self.split_shifts))

    def box(self, theta_max: float, z_prior: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """Bounds of the log-parameters (``theta`` first) on this window.

        Parameters
        ----------
        theta_max : float
            Upper end of the ``theta`` grid in rad.
        z_prior : numpy.ndarray
            Logarithms of the estimated linear parameters at the search's anchor.

        Returns
        -------
        tuple of numpy.ndarray or None
            Lower and upper bounds, or None without ``search_factor``.
        """
        if self.search_factor is None:
            return None
        fb = math.log(float(self.search_factor))
        return (np.r_[math.log(theta_max * 1e-3), z_prior - fb],
                np.r_[math.log(theta_max), z_prior + fb])


@dataclass(frozen=True, repr=False)
class Continuation(_Config):
    """The best first-window solutions followed on growing windows.

    Parameters
    ----------
    horizons : sequence of float, optional
        Growing windows in s after the first one (default ``(0.4, 1.0, 3.0)``: each
        moves the ringing's phase a little, so a solution follows its basin); then the
        whole record (or ``JointSearch.final_horizon``). ``()``: straight to it.
    fine_horizons : sequence of float, optional
        Windows inserted between the first and the last for a second, finer path from
        the best first-window solution (default ``(0.25, 0.6, 1.6)``; ``()``: one
        path). Both paths' ends compete on the whole record.
    candidates : int, optional
        Distinct first-window solutions continued, each within 1.25 times the best
        one's cost (default 3).
    ambiguity_starts : int, optional
        When the paths end in distinct minima of nearly equal cost (``ambiguous_``),
        up to this many more first-window solutions are continued (default 4; 0: off).
    direct : bool, optional
        Also follow the grid's best start on the main path's windows without the first
        window, where on the path's first window it ends below and apart from every
        candidate (default True; ``docs/design/joint-search.md``).
    """

    horizons: Sequence[float] = (0.4, 1.0, 3.0)
    fine_horizons: Sequence[float] = (0.25, 0.6, 1.6)
    candidates: int = 3
    ambiguity_starts: int = 4
    direct: bool = True

    def __post_init__(self) -> None:
        hs = _shifts("Continuation", "horizons", self.horizons)
        if any(b <= a for a, b in zip(hs, hs[1:], strict=False)):
            raise InputError(f"Continuation.horizons must increase, got {self.horizons!r}")
        self._set("horizons", hs)
        self._set("fine_horizons", _shifts("Continuation", "fine_horizons",
                                           self.fine_horizons))
        v.integer("Continuation.candidates", self.candidates, 1)
        v.integer("Continuation.ambiguity_starts", self.ambiguity_starts, 0)
        self._set("direct", _flag("Continuation", "direct", self.direct))

    def paths(self, first: float) -> list[list[float]]:
        """The continuation paths after a first window of ``first`` s.

        Parameters
        ----------
        first : float
            The first window in s.

        Returns
        -------
        list of list of float
            The horizons of the main path, then, when it differs, of the finer one.
        """
        short = [first, *self.horizons]
        paths = [short[1:]]
        if len(short) > 1:
            fine = sorted(set(short[1:]) | {float(x) for x in self.fine_horizons
                                            if short[0] < x < short[-1]})
            if fine != short[1:]:
                paths.append(fine)
        return paths


@dataclass(frozen=True, repr=False)
class Restarts(_Config):
    """Restarts of the best solution from other basins.

    Parameters
    ----------
    stiffness : sequence of float, optional
        ``k_sh`` multiplied by ``e^-x`` and ``e^x`` for every ``x`` (default
        ``(0.15, 0.4, 0.8)``; the whole-record cost is multimodal in the ringing's
        phase); ``()``: none. Each is screened on the longest short window first.
    long : sequence of float, optional
        ``k_sh`` multiplied by ``e^-x`` and ``e^x`` for every ``x``, each screened on a
        window twice the longest short one instead (default ``(0.1,)``). Longer
        records hold more periods of the ringing, and so more basins of its phase: on
        the second drive of ``benchmarks/real_drive.py`` at 30 dB, a lower basin with
        ``k_sh`` 5.8 % from the estimate's that the short window does not separate
        (docs/design/joint-search.md, item 10); ``()``: none.
    ringing : sequence of float, optional
        ``k_sh`` multiplied by ``e^x`` and ``J_M`` by ``e^(-x/2)``, and the opposite,
        for every ``x`` (default ``(0.08,)``): the ringing's frequency, about
        ``sqrt(k_sh / J_M)`` on a heavy load, moved by ``e^(3x/4)``, into a basin of
        its phase that a shift of ``k_sh`` alone does not reach (on the second drive
        of ``benchmarks/real_drive.py`` with a 10 % prior, trials 18 and 87:
        docs/design/joint-search.md, item 11); ``()``: none. Each is screened on the
        long window for up to 25 iterations, and only where that window holds at
        least half of the final data.
    friction : sequence of float, optional
        ``f_M / f_L`` multiplied by ``e^-x`` and ``e^x``, the sum kept (default
        ``(1.0,)``; the split shows only while the shaft crosses the backlash).
    misfit : bool, optional
        Run the whole search again from the fitted linear parameters when a residual
        is correlated beyond noise (a wrong basin) and the noise itself is not
        coloured; keep the fit of higher likelihood (default True). A fit refused as
        too far from the prior is refused without it.
    prior : bool, optional
        Restart first from the prior's linear parameters, ``theta`` and the added
        terms as found, and refit the profile interval's ends from there too
        (default True). The windows of the search can carry the linear parameters
        into the basin of a neighbouring ringing phase, ``k_sh`` 10-20 % off, whose
        whole-record cost is above the basin around the prior's (by 13.3 in
        ``-2 log L`` in a trial with Coulomb friction at 30 dB, where ``theta``
        stopped 6.1 % low; docs/design/joint-search.md, item 8).
    no_backlash : bool, optional
        Restart last from the prior's linear parameters with ``theta`` a thousandth of
        the solution's (:data:`NO_BACKLASH_SHARE`; default True): a drive with no
        backlash, or less than the records resolve, has its basin below where the
        grid's starts (``theta_max / points`` and up) and the first window's bounds
        (``theta_max / 1000`` and up) reach, and a search from there can end in a basin
        far worse (on the second drive of ``benchmarks/real_drive.py`` without
        backlash, ``k_sh`` x5.5 and refused; docs/design/real-drives.md, "A drive
        without backlash").

    Notes
    -----
    A restart gets a few iterations on the longest short window first (those of
    ``long`` on a window twice as long, those of ``ringing`` more iterations there)
    and goes on only if it comes below the solution it restarts from; it is refined
    on the whole record only if it beats it there, and kept only if it lowers the
    final cost.
    """

    stiffness: Sequence[float] = (0.15, 0.4, 0.8)
    long: Sequence[float] = (0.1,)
    ringing: Sequence[float] = (0.08,)
    friction: Sequence[float] = (1.0,)
    misfit: bool = True
    prior: bool = True
    no_backlash: bool = True

    def __post_init__(self) -> None:
        self._set("stiffness", _shifts("Restarts", "stiffness", self.stiffness))
        self._set("long", _shifts("Restarts", "long", self.long))
        self._set("ringing", _shifts("Restarts", "ringing", self.ringing))
        self._set("friction", _shifts("Restarts", "friction", self.friction))
        self._set("misfit", _flag("Restarts", "misfit", self.misfit))
        self._set("prior", _flag("Restarts", "prior", self.prior))
        self._set("no_backlash", _flag("Restarts", "no_backlash", self.no_backlash))

    def shifts(self, free: Sequence[str]) -> list[tuple[str, float]]:
        """The restarts in order: ``("prior", 0)`` (the prior's linear parameters),
        then ``("k_sh", d)`` and ``("f_M:f_L", d)`` log-shifts, then ``("theta", d)``
        (the prior's linear parameters, ``theta`` shifted by ``d`` in its logarithm).

        Parameters
        ----------
        free : sequence of str
            The estimated linear parameters (no stiffness restart without ``k_sh``).

        Returns
        -------
        list of tuple
            ``(kind, shift)`` pairs.
        """
        out = [("prior", 0.0)] if self.prior else []
        out += [("k_sh", d) for x in self.stiffness for d in (-x, x) if "k_sh" in free]
        out += [("f_M:f_L", d) for x in self.friction for d in (-x, x)]
        out += [("theta", math.log(NO_BACKLASH_SHARE))] if self.no_backlash else []
        return out

    def long_shifts(self, free: Sequence[str]) -> list[float]:
        """The log-shifts of ``k_sh`` screened on the long window (``long``).

        Parameters
        ----------
        free : sequence of str
            The estimated linear parameters (none without ``k_sh``).

        Returns
        -------
        list of float
            ``-x, x`` for every ``x`` of ``long``.
        """
        return [d for x in self.long for d in (-x, x)] if "k_sh" in free else []

    def ringing_shifts(self, free: Sequence[str]) -> list[dict[str, float]]:
        """The log-shifts of ``k_sh`` and ``J_M`` screened on the long window
        (``ringing``).

        Parameters
        ----------
        free : sequence of str
            The estimated linear parameters (none without both ``k_sh`` and ``J_M``).

        Returns
        -------
        list of dict
            ``{"k_sh": d, "J_M": -d / 2}`` for ``d`` in ``-x, x``, every ``x`` of
            ``ringing``.
        """
        if "k_sh" not in free or "J_M" not in free:
            return []
        return [{"k_sh": d, "J_M": -d / 2} for x in self.ringing for d in (-x, x)]


@dataclass(frozen=True, repr=False)
class JointSearch(_Config):
    """The joint estimator's search and refinement.

    Parameters
    ----------
    grid : ThetaGrid, optional
        The initial grid and starts.
    first : FirstHorizon, optional
        The refinement of every start on a short window.
    continuation : Continuation, optional
        The growing windows.
    restarts : Restarts, optional
        The restarts from other basins.
    start : {"auto", "rest", "steady"}, optional
        How the model starts on each record: ``"rest"`` from rest at the first sample
        (shaft centred in the backlash), ``"steady"`` in its own steady state under
        the torque held ``pre_window`` s before the step-down, ``"auto"`` (default)
        from rest where both speeds start there.
    pre_window : float, optional
        Span in s before the step-down fitted with a steady start (default 2).
    final_horizon : float or None, optional
        Window in s after the start of each record and every torque jump for the
        final refinement, the noise levels and the uncertainty (default None: the
        whole record). Shorter keeps a rattling shaft's likelihood closer to regular,
        at the price of a larger standard error.
    max_iter : int, optional
        Levenberg-Marquardt iterations of every stage after the first window
        (default 40).
    noise_iter : int, optional
        Re-estimations of the noise levels from the residuals, each followed by a
        refit (default 1).
    fd_step : float, optional
        Relative finite-difference step of the Jacobians, in (0, 0.1) (default 1e-6:
        the cost is only piecewise smooth in ``theta``).

    Examples
    --------
    A fit whose final stages take 1 s after each torque jump, without the second
    search that a misfitting residual sets off:

    >>> import backlashkit as bk
    >>> search = bk.JointSearch(restarts=bk.Restarts(misfit=False), final_horizon=1.0)
    >>> search.final_horizon
    1.0
    """

    grid: ThetaGrid = field(default_factory=ThetaGrid)
    first: FirstHorizon = field(default_factory=FirstHorizon)
    continuation: Continuation = field(default_factory=Continuation)
    restarts: Restarts = field(default_factory=Restarts)
    start: str = "auto"
    pre_window: float = 2.0
    final_horizon: float | None = None
    max_iter: int = 40
    noise_iter: int = 1
    fd_step: float = 1e-6

    def __post_init__(self) -> None:
        for name, kind in (("grid", ThetaGrid), ("first", FirstHorizon),
                           ("continuation", Continuation), ("restarts", Restarts)):
            if not isinstance(getattr(self, name), kind):
                raise InputError(f"{name} must be a {kind.__name__}, got "
                                 f"{type(getattr(self, name)).__name__}")
        if self.start not in ("auto", "rest", "steady"):
            raise InputError(f"start must be 'auto', 'rest' or 'steady', got "
                             f"{self.start!r}")
        self._set("pre_window", v.positive("pre_window", self.pre_window))
        if self.final_horizon is not None:
            self._set("final_horizon", v.positive("final_horizon",
                                                  self.final_horizon))
        v.integer("max_iter", self.max_iter, 1)
        v.integer("noise_iter", self.noise_iter, 0)
        step = v.positive("fd_step", self.fd_step)
        if not step < 0.1:
            raise InputError(f"fd_step must be < 0.1 (a relative step), got "
                             f"{self.fd_step!r}")
        self._set("fd_step", step)
        if self.continuation.horizons and not self.continuation.horizons[0] > self.first.horizon:
            raise InputError(
                "continuation.horizons must start after first.horizon "
                f"({self.first.horizon!r} s), got {self.continuation.horizons!r}"
            )
