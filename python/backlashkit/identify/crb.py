"""The Cramér-Rao bound of ``theta`` for a drive, an experiment and a noise level.

:func:`cramer_rao_bound` gives the lower bound on the standard deviation of any
unbiased estimate of ``theta`` (backlash half-width, rad) from both measured speeds,
with the linear parameters known or estimated jointly, under white or autoregressive
Gaussian noise; :class:`CramerRaoBound` holds it. Units are SI.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import partial

import numpy as np

from .. import validate as v
from ..actuator import CurrentLoop
from ..errors import InputError, SensitivityWarning
from ..plants import TwoMassDrive
from ._model import (
    LINEAR_PARAMS,
    drive_with,
    initial_states,
    packed_row,
    rel_std,
    steady_sensitivity,
)
from .noise import innovation_ratio, whiten

__all__ = ["CramerRaoBound", "cramer_rao_bound"]

ArrayLike = Sequence[float] | np.ndarray

#: Terms beyond the linear model that the bound can count as estimated: the Coulomb
#: torques of the drive and the current loop's time constant (``tau_i=``).
EXTRA_PARAMS = ("fc_M", "fc_L", "tau_i")

@dataclass(frozen=True)
class CramerRaoBound:
    """Cramér-Rao bound of an experiment.

    Parameters
    ----------
    names : tuple of str
        Estimated parameters, ``"theta"`` first.
    values : numpy.ndarray
        Their true values.
    fisher : numpy.ndarray
        Fisher information matrix in natural units (order ``names``), including the
        prior's information when one was given.
    noise_std : tuple of float
        White-noise standard deviations ``(s_M, s_L)`` in rad/s used.
    n_samples : int
        Samples per channel.

    Notes
    -----
    Fisher information of independent experiments adds: ``crb_a + crb_b`` is the bound
    for both experiments together (same parameter names).
    """

    names: tuple[str, ...]
    values: np.ndarray
    fisher: np.ndarray
    noise_std: tuple[float, float]
    n_samples: int

    @property
    def covariance(self) -> np.ndarray:
        """Inverse of the Fisher matrix: the bound on the covariance.

        Raises
        ------
        InputError
            If the Fisher matrix is singular: the experiment cannot tell the parameters
            apart (add another experiment's bound, or estimate fewer).
        """
        try:
            return np.linalg.inv(self.fisher)
        except np.linalg.LinAlgError:
            raise InputError(
                f"the Fisher information of {', '.join(self.names)} on this experiment is "
                "singular: it cannot tell them apart, so no bound exists; add another "
                "experiment's bound (crb_a + crb_b) or estimate fewer parameters") from None

    @property
    def std(self) -> dict[str, float]:
        """Bound on the standard deviation of every parameter."""
        d = np.sqrt(np.diag(self.covariance))
        return dict(zip(self.names, (float(x) for x in d), strict=True))

    @property
    def theta_std(self) -> float:
        """Bound on the standard deviation of ``theta`` in rad."""
        return self.std["theta"]

    def __repr__(self) -> str:
        # the dataclass's would print the Fisher matrix
        try:
            theta = f"theta_std={self.theta_std:.3g} rad"
        except InputError:  # singular: no bound
            theta = "singular"
        return (f"CramerRaoBound({theta}, names={self.names}, noise_std=("
                f"{self.noise_std[0]:.3g}, {self.noise_std[1]:.3g}) rad/s, "
                f"n_samples={self.n_samples})")

    def __add__(self, other: CramerRaoBound) -> CramerRaoBound:
        if not isinstance(other, CramerRaoBound) or other.names != self.names:
            raise InputError("only bounds over the same parameter names can be combined")
        return CramerRaoBound(self.names, self.values, self.fisher + other.fisher,
                              self.noise_std, self.n_samples + other.n_samples)


def cramer_rao_bound(
    drive: TwoMassDrive,
    t: ArrayLike,
    torque: ArrayLike,
    *,
    noise_std: tuple[float, float] | None = None,
    snr_db: float | tuple[float, float] | None = None,
    estimate: Sequence[str] | str = ("theta",),
    prior_rel_std: None | float | Mapping[str, float] = None,
    law: str = "paper",
    initial_state: ArrayLike | str | None = None,
    fd_step: float = 1e-6,
    noise_ar: ArrayLike | None = None,
    tau_i: float = 0.0,
) -> CramerRaoBound:
    """Cramér-Rao bound of ``theta`` from both measured speeds with white or AR noise.

    ``F = sum_c S_c^T S_c / s_c^2`` with ``S_c`` the sensitivity of speed ``c`` (motor,
    load) to the estimated parameters: exact, from the compiled kernel, where the model
    is its (paper A's law, Coulomb friction with no breakaway torque of its own or none,
    a current loop or none), else by central differences; with autoregressive noise
    (``noise_ar``) the sensitivities are whitened by ``A(q)`` first and ``s_c`` is the
    innovation's standard deviation (the likelihood of
    :class:`~backlashkit.identify.noise.ARNoise`, conditional on the first ``p`` samples).

    Parameters
    ----------
    drive : TwoMassDrive
        The true drive (with ``theta``).
    t, torque : array_like
        Uniform time grid in s and motor torque in N m of the experiment.
    noise_std : tuple of float, optional
        Noise standard deviations ``(s_M, s_L)`` in rad/s.
    snr_db : float or tuple of float, optional
        Instead of ``noise_std``: SNR in dB of ``(w_M, w_L)`` (one value for both),
        ``10 log10(mean(w^2) / noise_variance)`` over the record as in
        :func:`backlashkit.signals.add_noise`.
    estimate : sequence of str or "all", optional
        Parameters estimated: ``("theta",)`` (default, linear parameters known) or
        ``"all"`` (theta and the six linear parameters) or any list with ``"theta"``.
        The list may also hold ``"fc_M"``, ``"fc_L"`` (the drive's Coulomb torques,
        N m) and ``"tau_i"`` (the current loop's time constant, s): the bound of the
        larger model that :class:`~backlashkit.identify.joint.JointIdentifier` fits
        when it keeps those terms. Each must be non-zero.
    prior_rel_std : None, float or dict, optional
        Relative std of a Gaussian prior on the linear parameters, added to the
        information as ``1 / (rel_std p)^2`` (as in :class:`JointIdentifier`).
    law : {"paper", "no-pull"}, optional
        Contact law (default ``"paper"``).
    initial_state : array_like or "steady", optional
        State at ``t[0]``, known (default rest). ``"steady"``: the steady state under
        ``torque[0]`` of each model, which then moves with the parameters as in the
        joint estimator's ``start="steady"``. With a current loop the state has a
        fourth entry, the motor torque (default ``torque[0]``).
    fd_step : float, optional
        Relative central-difference step (default 1e-6), where the sensitivities are
        differenced.
    noise_ar : array_like, optional
        Coefficients ``a_1 .. a_p`` of ``A(q)`` of autoregressive noise (as
        :class:`~backlashkit.identify.noise.ARNoise` fits them, ``JointIdentifier.noise_ar_``):
        one row for both speeds or rows ``(w_M, w_L)``. ``noise_std`` and ``snr_db``
        then give the noise's own level, not its innovation's. Default: white noise.
    tau_i : float, optional
        Time constant in s of the current loop between the torque command and the
        motor (default 0: none). Known unless ``"tau_i"`` is in ``estimate``.

    Returns
    -------
    CramerRaoBound
        The bound (``.theta_std``, ``.fisher``, ``.names``).

    Raises
    ------
    InputError
        If the drive has no ``theta``, no or both noise levels are given, a name is
        unknown, a parameter to estimate is 0, ``noise_ar`` is not a stationary
        autoregression, a speed is 0 throughout where ``snr_db`` sets its noise, or
        the experiment carries no information on any parameter.
    """
    if not isinstance(drive, TwoMassDrive):
        raise InputError(f"drive must be a TwoMassDrive, got {type(drive).__name__}")
    theta = drive._require_theta()
    if (noise_std is None) == (snr_db is None):
        raise InputError("give exactly one of noise_std=(s_M, s_L) and snr_db")
    names = _estimated(estimate)
    tau_i = v.nonnegative("tau_i", tau_i)
    values = np.array([tau_i if n == "tau_i" else getattr(drive, n) for n in names], float)
    zero = [n for n, x in zip(names, values, strict=True) if not x > 0]
    if zero:
        raise InputError(f"cannot estimate parameter(s) {zero} at value 0 (e.g. theta = {theta!r})")
    h = v.positive("fd_step", fd_step)
    speeds, fisher_at = _exact_information(drive, names, tau_i, t, torque, law,
                                           initial_state, noise_ar)
    if fisher_at is None:
        speeds, sensitivity = _differenced(drive, names, values, h, tau_i, t, torque, law,
                                           initial_state)
        fisher_at = partial(_information, sensitivity, noise_ar=noise_ar)
    sig = _noise_levels(noise_std, snr_db, speeds)
    fisher = fisher_at(sig)
    if not np.any(fisher):
        raise InputError(
            f"the experiment carries no information on {', '.join(names)}: the model's "
            "speeds do not move with the parameters (does the torque move the drive?); "
            "choose an experiment that excites the drive through its backlash")
    if prior_rel_std is not None:
        rel = rel_std(prior_rel_std, LINEAR_PARAMS)
        for i, name in enumerate(names[1:], start=1):
            r = rel.get(name)
            if r is not None and r > 0:
                fisher[i, i] += 1.0 / (r * values[i]) ** 2
    return CramerRaoBound(names, values, fisher, (float(sig[0]), float(sig[1])),
                          int(np.size(speeds[0])))


def _information(sensitivity: np.ndarray, sig, noise_ar) -> np.ndarray:
    """``sum_c S_c^T S_c / s_c^2`` of the sensitivities ``(samples, 2, n)`` of both
    speeds and their noise levels ``sig``, whitened by ``A(q)`` first with
    autoregressive noise (``s_c`` then the innovation's std). With white noise one
    product of the ``(samples, 2 n)`` view serves both speeds, its two diagonal blocks:
    one BLAS call on rows twice as wide in place of two (docs/design/sensitivities.md,
    "The bound's information in one product")."""
    n = sensitivity.shape[2]
    ar, ratios = _autoregression(noise_ar)
    if ar is None:
        both = sensitivity.reshape(sensitivity.shape[0], 2 * n)
        gram = both.T @ both
        return gram[:n, :n] / sig[0] ** 2 + gram[n:, n:] / sig[1] ** 2
    fisher = np.zeros((n, n))
    for c, s in enumerate(sig):
        s = s * math.sqrt(ratios[c])
        sens = whiten(sensitivity[:, c, :].T, ar[c]).T
        fisher += sens.T @ sens / s**2
    return fisher


def _exact_information(drive, names, tau_i, t, torque, law, initial_state, noise_ar):
    """``((w_M, w_L), fisher_at)`` of the nominal drive, ``fisher_at(sig)`` the Fisher
    information at noise levels ``sig`` from the compiled kernel's exact sensitivities,
    where the model is in its scope (:func:`_in_scope`); else ``(None, None)``. With
    white noise the kernel sums the speeds' products as it walks
    (:func:`~backlashkit._sensitivity.trajectory_and_information`), and the
    sensitivities are never written out; autoregressive noise whitens them first
    (:func:`_exact`)."""
    from .._sensitivity import trajectory_and_information

    if noise_ar is not None:
        speeds, sens = _exact(drive, names, tau_i, t, torque, law, initial_state)
        return (None, None) if sens is None else (
            speeds, partial(_information, sens, noise_ar=noise_ar))
    if not _in_scope(drive, names, tau_i, law, initial_state):
        return None, None
    x, gram = _kernel(trajectory_and_information, drive, names, tau_i, t, torque,
                      initial_state)
    return (x[:, 0], x[:, 1]), lambda sig: gram[0] / sig[0] ** 2 + gram[1] / sig[1] ** 2


def _exact(drive, names, tau_i, t, torque, law, initial_state):
    """``((w_M, w_L), S)`` of the nominal drive, ``S`` the exact sensitivities
    ``(samples, 2, len(names))`` of both speeds (a view of the kernel's rows) of the
    compiled kernel, where the model is in its scope (:func:`_in_scope`); else
    ``(None, None)``. One sensitivity run of the estimated parameters alone (the speeds
    come from the same run), against ``2 n + 1`` simulations of central differences."""
    from .._sensitivity import trajectory_and_sensitivities

    if not _in_scope(drive, names, tau_i, law, initial_state):
        return None, None
    x, sens = _kernel(trajectory_and_sensitivities, drive, names, tau_i, t, torque,
                      initial_state)
    return (x[:, 0], x[:, 1]), sens[:, :2, :]


def _in_scope(drive, names, tau_i, law, initial_state) -> bool:
    """Whether the compiled sensitivities serve: paper A's law, breakaway torques tied
    to the Coulomb torques, a Coulomb torque estimated only where positive (``tau_i``
    only behind a loop: refused before), a known start or the steady one."""
    from .._sensitivity import COULOMB, PARAMS

    other_start = isinstance(initial_state, str) and initial_state != "steady"
    return not (law != "paper" or drive.fs_M is not None or drive.fs_L is not None
                or not set(names) <= set(PARAMS) or other_start
                or any(getattr(drive, n) == 0 for n in names if n in COULOMB))


def _kernel(run, drive, names, tau_i, t, torque, initial_state):
    """``run(drive, t, torque, ...)`` of the estimated parameters behind a current loop
    of time constant ``tau_i`` (0: none), quiet near grazing (as the differences are),
    its errors the bound's. The loop starts settled at the first torque where the
    start gives the drive's three states alone, as :func:`_speeds`'s (and the
    sensitivities' own default start). The steady start moves with the parameters: it
    starts with its sensitivity (:func:`~backlashkit.identify._model.steady_sensitivity`;
    the loop's torque is the held level, whatever the parameters)."""
    loop = CurrentLoop(tau_i) if tau_i > 0 else None
    start = {}
    if isinstance(initial_state, str):  # "steady" (_in_scope)
        level = float(np.ravel(torque)[0])
        x0 = initial_states(packed_row(drive, tau_i)[np.newaxis, :], level)[0]
        sens = steady_sensitivity(drive, level, names)
        start["initial_sensitivity"] = np.vstack([sens, np.zeros((x0.size - 3, len(names)))])
    else:
        x0 = None if initial_state is None else np.asarray(initial_state, float).ravel()
        if loop is not None and x0 is not None and x0.size == 3:
            x0 = np.append(x0, np.ravel(torque)[:1])
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", SensitivityWarning)
            return run(drive, t, torque, initial_state=x0, params=names, actuator=loop,
                       **start)
    except ValueError as exc:
        raise InputError(f"cannot simulate the drive for the bound: {exc}") from exc


def _differenced(drive, names, values, h, tau_i, t, torque, law, initial_state):
    """As :func:`_exact`, by central differences of relative step ``h``."""
    points = [values]
    for i in range(len(names)):
        for sgn in (1.0, -1.0):
            x = values.copy()
            x[i] *= 1.0 + sgn * h
            points.append(x)
    speeds = _speeds(drive, names, points, tau_i, t, torque, law, initial_state)
    return speeds[0], np.stack([
        np.column_stack([(speeds[1 + 2 * i][c] - speeds[2 + 2 * i][c]) / (2 * h * values[i])
                         for i in range(len(names))]) for c in (0, 1)], axis=1)


def _speeds(drive, names, points, tau_i, t, torque, law, initial_state
            ) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(w_M, w_L)`` of the drive at each parameter point (order ``names``)."""
    from ..simulate import simulate_packed

    models = [(drive_with(drive, [m for m in names if m != "tau_i"],
                          np.array([x for m, x in zip(names, p, strict=True) if m != "tau_i"])),
               float(p[names.index("tau_i")]) if "tau_i" in names else tau_i)
              for p in points]
    t_arr, ts = v.time_grid(t)
    u = np.asarray(torque, float)
    if u.shape != t_arr.shape:
        raise InputError(f"torque must have the shape of t {t_arr.shape}, got {u.shape}")
    rows = np.stack([packed_row(d, ti) for d, ti in models])
    if isinstance(initial_state, str):
        if initial_state != "steady":
            raise InputError(f"initial_state must be an array or 'steady', got {initial_state!r}")
        x0 = initial_states(rows, float(u[0]))
    elif initial_state is None:
        x0 = initial_states(rows, None, float(u[0]))
    else:
        x = np.asarray(initial_state, float).ravel()
        if tau_i > 0 and x.size == 3:  # the loop starts at the held torque
            x = np.append(x, u[0])
        x0 = np.tile(x, (len(rows), 1))
    try:
        states = simulate_packed(2, rows, float(t_arr[0]), ts, u[np.newaxis, :], x0,
                                 law=law, workers=None)
    except ValueError as exc:
        raise InputError(f"cannot simulate the drive for the bound: {exc}") from exc
    return [(x[:, 0], x[:, 1]) for x in states]


def _estimated(estimate) -> tuple[str, ...]:
    """The estimated parameters' names, ``theta`` first, in the fitted order."""
    all_names = ("theta", *LINEAR_PARAMS, *EXTRA_PARAMS)
    if isinstance(estimate, str):
        if estimate != "all":
            raise InputError(f"estimate must be 'all' or a sequence of names, got {estimate!r}"
                             f" (one name is a sequence too: ({estimate!r},))")
        return ("theta", *LINEAR_PARAMS)
    names = tuple(estimate)
    bad = [n for n in names if n not in all_names]
    if bad or "theta" not in names or len(set(names)) != len(names):
        raise InputError(
            f"estimate must list distinct names among {', '.join(all_names)} including "
            f"'theta', got {estimate!r}"
        )
    return tuple(n for n in all_names if n in names)


def _noise_levels(noise_std, snr_db, nominal) -> tuple[float, float]:
    """Noise std ``(s_M, s_L)``: given, or from the SNR of the nominal speeds
    ``(w_M, w_L)``."""
    if noise_std is not None:
        try:
            s_m, s_l = noise_std
        except (TypeError, ValueError):
            raise InputError(f"noise_std must be a pair (s_M, s_L), got {noise_std!r}") from None
        return (v.positive("noise_std[0] (s_M)", s_m), v.positive("noise_std[1] (s_L)", s_l))
    snr = (snr_db, snr_db) if np.ndim(snr_db) == 0 else tuple(snr_db)
    if len(snr) != 2:
        raise InputError(f"snr_db must be a number or a pair (w_M, w_L), got {snr_db!r}")
    levels = []
    for w, s, name in zip(nominal, snr, ("w_M", "w_L"), strict=True):
        power = float(np.mean(w**2))
        if not power > 0:
            raise InputError(
                f"snr_db: the model's {name} is 0 over the whole experiment, so an SNR gives "
                "it no noise level; give noise_std=(s_M, s_L) instead, or a torque that "
                "moves the drive")
        levels.append(math.sqrt(power / 10.0 ** (v.finite_scalar("snr_db", s) / 10.0)))
    return (levels[0], levels[1])


def _autoregression(noise_ar) -> tuple[np.ndarray | None, list[float]]:
    """``A(q)`` per speed (rows ``w_M, w_L``) and its innovation ratios, or None."""
    if noise_ar is None:
        return None, [1.0, 1.0]
    ar = np.atleast_2d(np.asarray(noise_ar, float))
    if ar.shape[0] == 1:
        ar = np.repeat(ar, 2, axis=0)
    if ar.ndim != 2 or ar.shape[0] != 2 or ar.shape[1] < 1 or not np.isfinite(ar).all():
        raise InputError(
            "noise_ar must be the coefficients a_1 .. a_p of A(q), one row for both "
            f"speeds or two rows (w_M, w_L), got {noise_ar!r}"
        )
    try:
        return ar, [innovation_ratio(row) for row in ar]
    except InputError as exc:
        raise InputError(f"noise_ar: {exc}") from None
