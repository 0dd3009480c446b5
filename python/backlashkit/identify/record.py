"""Measured experiments and the checks that refuse an unusable one.

A :class:`Record` holds one uniformly sampled experiment: the motor torque and the two
measured speeds, or the two measured angles of encoders
(:meth:`Record.from_positions`). :func:`as_records` turns what a user passes (a Record, a tuple
``(t, torque, w_motor, w_load)`` or a sequence of them) into checked Records; every
estimator calls it, so the library and the command line refuse the same records.

Units are SI: s, N m, rad/s, rad.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from .. import validate as v
from ..errors import InputError, Option
from ..plants import TwoMassDrive
from .clipping import check_not_clipped
from .quantum import speed_quantum
from .torque import check_torque_noise, torque_noise_std

__all__ = [
    "Record",
    "as_records",
    "check_distinct",
    "check_prior",
    "check_sampling",
    "check_speeds_vary",
    "check_spikes",
]

ArrayLike = Sequence[float] | np.ndarray


@dataclass(frozen=True, eq=False)
class Record:
    """One step-down experiment: uniformly sampled torque and measured speeds.

    Parameters
    ----------
    t : array_like
        Uniform, strictly increasing time grid in s.
    torque : array_like
        Motor torque in N m (zero-order hold), one sample per ``t``.
    w_motor, w_load : array_like
        Measured motor and load speeds in rad/s.
    name : str, optional
        Name used in messages (e.g. the file name).
    phi_motor, phi_load : array_like, optional
        Measured motor and load angles in rad (encoders), set by
        :meth:`from_positions` or :meth:`with_positions`. Where they are given the
        joint estimator fits them, not the speeds: ``w_motor`` and ``w_load`` are then
        their differences over each sample, the mean speeds over the sample before.
    quantum : float, optional
        Step of the angles in rad (``2 pi`` over the encoder's counts per
        revolution); 0 where they are not quantised or it is not known.
    """

    t: np.ndarray
    torque: np.ndarray
    w_motor: np.ndarray
    w_load: np.ndarray
    name: str = field(default="record")
    phi_motor: np.ndarray | None = field(default=None, repr=False)
    phi_load: np.ndarray | None = field(default=None, repr=False)
    quantum: float = 0.0

    def __post_init__(self) -> None:
        t, _ = v.time_grid(self.t, name=f"{self.name}: t", min_samples=3)
        object.__setattr__(self, "t", t)
        cols = ["torque", "w_motor", "w_load"]
        if (self.phi_motor is None) != (self.phi_load is None):
            raise InputError(f"{self.name}: give both phi_motor and phi_load, or neither")
        if self.phi_motor is not None:
            cols += ["phi_motor", "phi_load"]
        for col in cols:
            arr = v.finite_array(f"{self.name}: {col}", getattr(self, col))
            if arr.size != t.size:
                raise InputError(
                    f"{self.name}: {col} must have one sample per t ({t.size}), got {arr.size}"
                )
            object.__setattr__(self, col, arr)
        q = float(self.quantum)
        if not (math.isfinite(q) and q >= 0):
            raise InputError(f"{self.name}: quantum must be a finite angle >= 0 in rad, "
                             f"got {self.quantum!r}")

    @property
    def ts(self) -> float:
        """Sample time in s."""
        return float((self.t[-1] - self.t[0]) / (self.t.size - 1))

    def __repr__(self) -> str:
        # the dataclass's would print its arrays
        what = "encoder angles" if self.has_positions else "speeds"
        return (f"Record({self.name!r}, {self.t.size} samples at {self.ts:g} s from "
                f"t = {self.t[0]:g} s, {what})")

    @cached_property
    def speed_quanta(self) -> tuple[float, float]:
        """The steps of the motor and load speeds where an encoder's differenced counts
        quantise them, in rad/s (:func:`~backlashkit.identify.quantum.speed_quantum`;
        0 for a speed that is not quantised). Found once per record: it sorts each
        speed, and the record's checks and the fit each ask."""
        return speed_quantum(self.w_motor), speed_quantum(self.w_load)

    @cached_property
    def torque_noise(self) -> float:
        """The torque's noise std in N m
        (:func:`~backlashkit.identify.torque.torque_noise_std`). Found once per record:
        its checks and the step-down's location each ask, and it takes medians over
        the whole record."""
        return torque_noise_std(self.torque)

    @property
    def has_positions(self) -> bool:
        """Whether the record holds measured angles (fitted instead of the speeds)."""
        return self.phi_motor is not None

    @classmethod
    def from_positions(cls, t: ArrayLike, torque: ArrayLike, phi_motor: ArrayLike,
                       phi_load: ArrayLike, *, counts_per_rev: float | None = None,
                       name: str = "record") -> Record:
        """A record of measured angles: encoder counts, or angles in rad.

        Parameters
        ----------
        t, torque : array_like
            As for :class:`Record`.
        phi_motor, phi_load : array_like
            The motor's and load's angles: in rad, or in counts with
            ``counts_per_rev``.
        counts_per_rev : float, optional
            Counts per revolution of both encoders: the angles are counts, and their
            quantum is ``2 pi / counts_per_rev`` rad.
        name : str, optional
            Name used in messages.

        Returns
        -------
        Record
            With ``w_motor``, ``w_load`` the angles' differences over each sample
            divided by the sample time (the first sample repeats the second's).
        """
        quantum = 0.0
        phi = [v.finite_array(f"{name}: {c}", x)
               for c, x in (("phi_motor", phi_motor), ("phi_load", phi_load))]
        if counts_per_rev is None and all(_counts_like(x) for x in phi):
            raise InputError(
                f"{name}: phi_motor and phi_load hold whole numbers only (a travel of up "
                f"to {max(float(np.ptp(x)) for x in phi):.6g}): encoder counts read as "
                "rad? give ", Option("counts_per_rev", None), " N (the encoders' counts per "
                "revolution)")
        if counts_per_rev is not None:
            cpr = v.positive("counts_per_rev", counts_per_rev)
            quantum = 2 * math.pi / cpr
            phi = [x * quantum for x in phi]
        tt, _ = v.time_grid(t, name=f"{name}: t", min_samples=3)
        ts = float((tt[-1] - tt[0]) / (tt.size - 1))
        w = [np.r_[x[1:2] - x[0:1], np.diff(x)] / ts if x.size > 1 else x for x in phi]
        return cls(tt, torque, w[0], w[1], name, phi[0], phi[1], quantum)

    def with_positions(self, quantum: float = 0.0) -> Record:
        """The record with its angles: the speeds summed over the samples.

        For speeds that are differences of encoder counts, ``w_k = (phi_k -
        phi_(k-1)) / Ts``: their running sum gives the angles back exactly, from 0 at the
        first sample (whose own speed is not used).

        Parameters
        ----------
        quantum : float, optional
            Step of the angles in rad (the speeds' step times the sample time).

        Returns
        -------
        Record
            Itself where it already holds angles.
        """
        if self.has_positions:
            return self
        ts = self.ts
        phi = [np.r_[0.0, np.cumsum(w[1:]) * ts] for w in (self.w_motor, self.w_load)]
        return Record(self.t, self.torque, self.w_motor, self.w_load, self.name,
                      phi[0], phi[1], quantum)


#: Angles in rad that are whole numbers over at least this travel (16 turns) are
#: counts: an angle in rad is a whole number by chance alone at most at a few samples.
COUNTS_LIKE_TRAVEL = 100.0


def _counts_like(phi: np.ndarray) -> bool:
    """Whether angles look like encoder counts read as rad (:data:`COUNTS_LIKE_TRAVEL`)."""
    return bool(np.ptp(phi) >= COUNTS_LIKE_TRAVEL and np.all(phi == np.round(phi)))


def _as_record(rec: Record | Sequence[ArrayLike], i: int) -> Record:
    if isinstance(rec, Record):
        return rec
    try:
        t, torque, w_motor, w_load = rec
    except (TypeError, ValueError):
        raise InputError(
            f"records[{i}] must be a Record or a tuple (t, torque, w_motor, w_load)"
        ) from None
    return Record(t, torque, w_motor, w_load, name=f"records[{i}]")


def check_speeds_vary(rec: Record) -> None:
    """Refuse a record with a constant speed: it cannot show the drive's response.

    Parameters
    ----------
    rec : Record
        The record (its ``name`` goes into the message).

    Raises
    ------
    InputError
        If ``w_motor`` or ``w_load`` takes one value only.
    """
    for name, w in (("w_motor", rec.w_motor), ("w_load", rec.w_load)):
        if not np.ptp(w) > 0:
            raise InputError(
                f"{rec.name}: {name} is constant ({float(w[0]):.6g} rad/s): the speeds "
                "must respond to the torque; check the columns"
            )

#: A speed sample farther than this many noise std (and than SPIKE_RANGE of the
#: speed's range) from the median of itself and its two neighbours is a spike.
SPIKE_SIGMAS = 30.0
SPIKE_RANGE = 0.2


#: Steps of a speed below this share of its largest value are rounding, not a quantum:
#: speeds differenced from angles in rad (counts times ``2 pi / N``) differ by a few
#: units in their last place where the counts are the same, far below this.
ROUNDING_STEP = 1e-9


def check_spikes(rec: Record) -> None:
    """Refuse a record with a single-sample spike in a speed (a glitch of the sensor).

    The median of three consecutive samples follows steps and the drive's impacts but
    not a lone sample off the curve; least squares would chase such a glitch.

    Parameters
    ----------
    rec : Record
        The record (its ``name`` goes into the message).

    Raises
    ------
    InputError
        If a sample of ``w_motor`` or ``w_load`` is off the median of itself and its
        neighbours by more than :data:`SPIKE_SIGMAS` noise std (robust: median absolute
        deviations; at least the quantum of quantised speeds) and :data:`SPIKE_RANGE`
        of the speed's range.
    """
    for name, w in (("w_motor", rec.w_motor), ("w_load", rec.w_load)):
        if w.size < 3:
            continue
        with np.errstate(over="ignore", invalid="ignore"):
            a, b, c = w[:-2], w[1:-1], w[2:]  # median of three, elementwise
            mid = np.maximum(np.minimum(a, b), np.minimum(np.maximum(a, b), c))
            off = np.abs(w[1:-1] - mid)
            # the noise from where the speed moves: a drive resting at exactly 0 (an
            # encoder at standstill) would pull the median deviation to 0; quantised
            # speeds (an encoder's counts) have their quantum as the floor
            moving = ~((a == b) & (b == c))
            sigma = 1.4826 * float(np.median(off[moving])) if moving.any() else 0.0
            lo, hi = np.percentile(w, [0.1, 99.9])
            span = float(hi - lo)
            steps = np.abs(np.diff(w))
            # speeds differenced from angles in rad differ by rounding where the counts
            # are equal: the quantum is the smallest step above that, or the angles'
            moves = steps[steps > ROUNDING_STEP * max(abs(float(lo)), abs(float(hi)))]
            quantum = max(float(moves.min()) if moves.size else 0.0, rec.quantum / rec.ts)
            sigma = max(sigma, quantum)
            bad = (off > SPIKE_SIGMAS * sigma) & (off > SPIKE_RANGE * span)
        if bad.any():
            k = int(np.argmax(off)) + 1
            raise InputError(
                f"{rec.name}: {name} has {int(bad.sum())} single-sample spike(s), the largest "
                f"at t = {rec.t[k]:.6g} s (sample {k}: {w[k]:.6g} rad/s, its neighbours "
                f"{w[k - 1]:.6g} and {w[k + 1]:.6g}): a sensor glitch; remove those samples "
                "(empty cells, then --resample linear bridges them)"
            )


def check_sampling(prior: TwoMassDrive, rec: Record) -> None:
    """Refuse a record sampled too slowly to show the drive's ringing.

    The ringing frequency ``sqrt(k_sh (1 / J_M + 1 / J_L))`` of the prior must lie below
    the Nyquist frequency ``pi / Ts``: otherwise no sample sees an impact, and a time
    column in ms read as s is the likely cause.

    Parameters
    ----------
    prior : TwoMassDrive
        The prior (its linear parameters).
    rec : Record
        The record (its ``name`` goes into the message).

    Raises
    ------
    InputError
        If ``Ts`` is longer than half the ringing period.
    """
    omega = prior.ringing_frequency
    if rec.ts * omega > math.pi:
        raise InputError(
            f"{rec.name}: the sample time {rec.ts:.6g} s cannot resolve the drive's ringing "
            f"at {omega:.4g} rad/s (period {2 * math.pi / omega:.3g} s, from the prior's k_sh, "
            f"J_M, J_L): sample faster than {math.pi / omega:.3g} s, or check the time unit "
            "(a time column in ms reads as s) and the prior's units"
        )

def check_distinct(records: Sequence[Record]) -> None:
    """Refuse a record given twice: a joint fit would count its data twice and report a
    standard error too small by sqrt(2), and no method gains from it.

    Parameters
    ----------
    records : sequence of Record
        The records.

    Raises
    ------
    InputError
        If two records hold the same samples (``t``, torque and both speeds).
    """
    seen: dict[bytes, str] = {}
    for rec in records:
        key = b"".join(np.ascontiguousarray(x, float).tobytes()
                       for x in (rec.t, rec.torque, rec.w_motor, rec.w_load))
        if key in seen:
            raise InputError(
                f"{rec.name} holds the same data as {seen[key]}: give every record once "
                "(the joint fit would count it twice and understate the uncertainty)"
            )
        seen[key] = rec.name


def as_records(records, what: str = "records", *, prior=None) -> list[Record]:
    """Records of ``records``, each checked usable.

    Parameters
    ----------
    records : Record, tuple or sequence of them
        What the user passed: a :class:`Record`, a tuple ``(t, torque, w_motor,
        w_load)`` or a sequence of them.
    what : str, optional
        Its name in messages (default ``"records"``).
    prior : TwoMassDrive, optional
        When given, each record must sample fast enough for its ringing
        (:func:`check_sampling`).

    Returns
    -------
    list of Record
        The records, in order (a tuple becomes a Record named ``records[i]``).

    Raises
    ------
    InputError
        If ``records`` is none of those, is empty, holds a record twice
        (:func:`check_distinct`), or a record is clipped, has a constant speed, a spike
        or a noisy torque, or samples too slowly for ``prior``.
    """
    if records is None or isinstance(records, (str, bytes, os.PathLike)):
        hint = (" (a file? read it with backlashkit.read_records)"
                if records is not None else "")
        raise InputError(
            f"{what} must be a Record or a sequence of Records, got "
            f"{type(records).__name__}{hint}"
        )
    if isinstance(records, np.ndarray):
        raise InputError(
            f"{what} must be a Record or a sequence of Records, got a {records.shape} "
            "array: for columns t, torque, w_motor, w_load give Record(*array.T)")
    if isinstance(records, Record) or (
        isinstance(records, tuple)
        and len(records) == 4
        and all(not isinstance(x, (Record, tuple)) and np.ndim(x) == 1 for x in records)
    ):
        records = [records]  # a single record
    recs = list(records)
    if not recs:
        raise InputError(f"{what} must hold at least one record, got none")
    out = [_as_record(r, i) for i, r in enumerate(recs)]
    check_distinct(out)
    for rec in out:  # what no model can fit is refused rather than answered
        check_not_clipped(rec)
        check_speeds_vary(rec)
        check_spikes(rec)
        check_torque_noise(rec)
        if prior is not None:
            check_sampling(prior, rec)
    return out


def check_prior(prior: TwoMassDrive) -> TwoMassDrive:
    """Refuse a prior that is not a :class:`~backlashkit.TwoMassDrive`.

    Parameters
    ----------
    prior : TwoMassDrive
        The prior drive.

    Returns
    -------
    TwoMassDrive
        ``prior``.

    Raises
    ------
    InputError
        If it is not one.
    """
    if not isinstance(prior, TwoMassDrive):
        raise InputError(f"prior must be a TwoMassDrive, got {type(prior).__name__}")
    return prior
