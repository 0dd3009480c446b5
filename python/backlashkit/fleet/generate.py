"""A generator of fleet data: drives of paper A's model, wearing, tested every week.

Each drive is paper A's drive (:data:`backlashkit.papers.ravanbod2002.P_TRUE`, Section 5)
with its six linear parameters spread around the catalogue values, an initial backlash
half-width spread around paper A's 3.49e-2 rad, and a backlash that grows linearly at a
drive-specific rate. Every week it runs paper A's test: two step-down records from rest
(0.157 N m and 0.942 N m held ``hold`` s, then 0), white noise at paper A's SNRs. The
files are those a plant would log: one CSV per record (``t,torque,w_motor,w_load``, the
format ``backlashkit simulate --experiment step-down`` writes), a ``PRIOR.toml`` per
drive holding the catalogue values (the format of ``examples/paper_drive.toml``
without ``theta``), and ``MANIFEST.csv`` (:mod:`backlashkit.fleet.manifest`); the truth
goes to ``TRUTH.csv`` beside it, for studies of the estimates.

Seeds: drive ``d`` draws from child ``d`` of ``SeedSequence(seed).spawn(n_drives)``
(spawned again into its parameters and one child per week), so a drive's data do not
depend on how many drives or weeks are generated with it, nor on the executor.
"""

from __future__ import annotations

import datetime as dt
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .. import signals
from .. import validate as v
from ..errors import InputError, SensitivityWarning
from ..identify.record import Record
from ..io import write_csv
from ..papers.ravanbod2002 import A1, A2, P_TRUE, SNR1, SNR2, THETA, TS
from ..parallel import map_tasks, root_seed
from ..plants import TwoMassDrive
from .manifest import MANIFEST_COLUMNS

__all__ = ["FleetTruth", "generate_fleet", "DAYS_PER_YEAR"]

#: Days per (Julian) year: the unit of the wear rates, rad per year.
DAYS_PER_YEAR = 365.25
#: Default fastest growth of the half-width, rad per year: at 0.02 rad/year paper A's
#: 3.49e-2 rad backlash grows by half in under a year, the fast end of what a weekly
#: test is meant to catch; rates are uniform on [0, max_rate].
DEFAULT_MAX_RATE = 0.02
#: Default relative spread of the linear parameters around the catalogue (uniform on
#: +-10 %: paper A's smallest prior error, Err_p = 0.1).
DEFAULT_SPREAD = 0.1
#: Default relative spread of the initial half-width around paper A's (uniform, +-20 %).
DEFAULT_THETA_SPREAD = 0.2
#: Default time the torque is held before the step-down, s. Paper A holds 40 s; the
#: joint fit reads the step-down and needs only the level to have settled (the ringing
#: decays in about 1.5 s on paper A's drive), so 10 s keeps the files and the fits small.
DEFAULT_HOLD = 10.0
#: Most samples a generated record may have (``2 hold / TS``): a CSV of 2e7 rows of four
#: numbers, and the fleet writes two a drive and week.
MAX_HOLD_SAMPLES = 2e7
#: The prior's header: where the values come from.
_PRIOR_HEADER = ("# Catalogue values of the drive (paper A, Section 5), SI units; the\n"
                 "# backlash half-width theta is what the tests identify.\n")


@dataclass(frozen=True)
class FleetTruth:
    """What :func:`generate_fleet` wrote and the truth behind it.

    Attributes
    ----------
    manifest : pathlib.Path
        The ``MANIFEST.csv`` written.
    drives : list of str
        Drive ids, in order.
    theta0 : numpy.ndarray
        Half-width of each drive at its first test, rad.
    rate : numpy.ndarray
        Growth of each drive's half-width, rad per year.
    params : list of dict
        Each drive's true linear parameters (SI units).
    dates : list of datetime.date
        The test dates (the same for every drive).
    """

    manifest: Path
    drives: list[str]
    theta0: np.ndarray
    rate: np.ndarray
    params: list[dict[str, float]]
    dates: list[dt.date]

    def __repr__(self) -> str:
        # the dataclass's prints every drive's parameters (hundreds of characters)
        return (f"FleetTruth({len(self.drives)} drives, {len(self.dates)} weekly tests from "
                f"{self.dates[0]}, manifest {str(self.manifest)!r})")


def _draw(seed: np.random.SeedSequence, spread: float, theta_spread: float,
          max_rate: float) -> tuple[dict[str, float], float, float]:
    rng = np.random.default_rng(seed)
    x = rng.uniform(-1.0, 1.0, len(P_TRUE))
    params = {k: val * (1.0 + spread * xi) for (k, val), xi in zip(P_TRUE.items(), x,
                                                                    strict=True)}
    theta0 = THETA * (1.0 + theta_spread * rng.uniform(-1.0, 1.0))
    return params, theta0, rng.uniform(0.0, max_rate)


def _record(drive: TwoMassDrive, t: np.ndarray, a: float, hold: float,
            snr: tuple[float, float], seed: np.random.SeedSequence) -> Record:
    with warnings.catch_warnings():  # a grazing pass is part of what a real drive does
        warnings.simplefilter("ignore", SensitivityWarning)
        r = drive.simulate(t, signals.step_down(t, a, t_s=hold))
    s_m, s_l = seed.spawn(2)
    return Record(t, r.torque, signals.add_noise(r.w_motor, snr[0], rng=s_m),
                  signals.add_noise(r.w_load, snr[1], rng=s_l))


def _write_prior(path: Path, prior: dict[str, float], force: bool) -> None:
    body = "".join(f"{k} = {val!r}\n" for k, val in prior.items())
    with open(path, "w" if force else "x", encoding="utf-8") as fh:
        fh.write(_PRIOR_HEADER + "\n[drive]\n" + body)


def _one_drive(task: tuple[Any, ...], seed: np.random.SeedSequence) -> list[list[str]]:
    """Write one drive's prior and records; return its manifest rows."""
    root, name, dates, cfg = task
    s_params, *s_weeks = seed.spawn(1 + len(dates))
    params, theta0, rate = _draw(s_params, cfg["spread"], cfg["theta_spread"],
                                 cfg["max_rate"])
    folder = Path(root) / name
    folder.mkdir(exist_ok=True)
    _write_prior(folder / "PRIOR.toml", P_TRUE, cfg["force"])
    t = signals.time_grid(2 * cfg["hold"], TS)
    rows = []
    for day, s_week in zip(dates, s_weeks, strict=True):
        years = (day - dates[0]).days / DAYS_PER_YEAR
        drive = TwoMassDrive(**params, theta=theta0 + rate * years)
        files = []
        for k, (a, snr, s_rec) in enumerate(zip((A1, A2), (cfg["snr1"], SNR2),
                                                s_week.spawn(2), strict=True), start=1):
            rec = _record(drive, t, a, cfg["hold"], snr, s_rec)
            rel = f"{name}/{day.isoformat()}_step{k}.csv"
            write_csv(Path(root) / rel, {"t": rec.t, "torque": rec.torque,
                                         "w_motor": rec.w_motor, "w_load": rec.w_load},
                      force=cfg["force"])
            files.append(rel)
        rows.append([name, day.isoformat(), "|".join(files), f"{name}/PRIOR.toml"])
    return [rows, params, theta0, rate]


def _write_table(path: Path, header: list[str], rows: list[list[Any]], force: bool) -> None:
    text = ",".join(header) + "\n" + "".join(",".join(map(str, r)) + "\n" for r in rows)
    with open(path, "w" if force else "x", encoding="utf-8", newline="") as fh:
        fh.write(text)


def _snr_pair(snr1: Any) -> tuple[float, float]:
    """``snr1`` as two SNRs in dB."""
    pair = v.finite_array("snr1", snr1)
    if pair.size != 2 or np.any(np.abs(pair) > signals.SNR_LIMIT_DB):
        raise InputError(f"snr1 must be two SNRs in dB, (w_M, w_L), each within "
                         f"+-{signals.SNR_LIMIT_DB:g}, got {snr1!r}")
    return float(pair[0]), float(pair[1])


def _start_date(start: Any) -> dt.date:
    """``start`` as a date (a ``datetime.date`` or an ISO string such as 2026-01-05)."""
    if isinstance(start, str):
        try:
            return dt.date.fromisoformat(start)
        except ValueError:
            pass
    elif isinstance(start, dt.date) and not isinstance(start, dt.datetime):
        return start
    raise InputError(f"start must be a date, datetime.date(2026, 1, 5) or '2026-01-05', got "
                     f"{start!r}")


def generate_fleet(
    n_drives: int,
    n_weeks: int,
    *,
    seed: int,
    out: str | Path,
    spread: float = DEFAULT_SPREAD,
    theta_spread: float = DEFAULT_THETA_SPREAD,
    max_rate: float = DEFAULT_MAX_RATE,
    hold: float = DEFAULT_HOLD,
    snr1: tuple[float, float] = SNR1,
    start: dt.date | str = dt.date(2026, 1, 5),
    force: bool = False,
    executor: Any = None,
    jobs: int | None = None,
) -> FleetTruth:
    """Write a fleet's weekly step-down tests, priors and manifest into ``out``.

    Parameters
    ----------
    n_drives : int
        Drives (>= 1), named ``drive-001``, ``drive-002``, ...
    n_weeks : int
        Weekly tests per drive (>= 1).
    seed : int, numpy.random.SeedSequence or numpy.random.Generator
        Root seed (module docstring; :func:`~backlashkit.parallel.root_seed`).
    out : str or pathlib.Path
        Folder to write into (made if missing; its parent must exist).
    spread : float, optional
        Relative spread of the linear parameters around paper A's, uniform on
        ``+-spread`` (default :data:`DEFAULT_SPREAD`), in [0, 1).
    theta_spread : float, optional
        Relative spread of the initial half-width around 3.49e-2 rad (default
        :data:`DEFAULT_THETA_SPREAD`), in [0, 1).
    max_rate : float, optional
        Growth rates in rad per year are uniform on ``[0, max_rate]`` (default
        :data:`DEFAULT_MAX_RATE`), >= 0.
    hold : float, optional
        Seconds each torque level is held before its step-down; each record lasts
        ``2 hold`` s at paper A's 1 ms (default :data:`DEFAULT_HOLD`; paper A: 40).
    snr1 : tuple of float, optional
        SNR in dB of ``(w_M, w_L)`` on the 0.157 N m record (default paper A's 17.4 and
        6.43); the 0.942 N m record has paper A's 35.7 and 35.6 dB.
    start : datetime.date or str, optional
        Date of the first test (default 2026-01-05; an ISO string such as
        ``"2026-01-05"`` too); one test every 7 days.
    force : bool, optional
        Overwrite existing files (default False: refuse).
    executor : concurrent.futures.Executor or dask.distributed.Client, optional
        Where to simulate the drives (:mod:`backlashkit.parallel`); the files do not
        depend on it.
    jobs : int, optional
        Local worker processes instead of ``executor``.

    Returns
    -------
    FleetTruth
        The manifest's path and each drive's truth (also written to ``TRUTH.csv``).

    Raises
    ------
    InputError
        If a count, spread, rate, hold, SNR, date or seed is out of range or of the
        wrong kind (checked before any file is written), or a file exists and
        ``force`` is False.
    """
    v.integer("n_drives", n_drives, 1)
    v.integer("n_weeks", n_weeks, 1)
    for name, value in (("spread", spread), ("theta_spread", theta_spread)):
        if not 0.0 <= v.nonnegative(name, value) < 1.0:
            raise InputError(f"{name} must be in [0, 1) (a relative spread), got {value!r}")
    v.nonnegative("max_rate", max_rate)
    if v.positive("hold", hold) * 2 / TS > MAX_HOLD_SAMPLES:
        raise InputError(f"hold must be at most {MAX_HOLD_SAMPLES * TS / 2:g} s (each record "
                         f"is 2 hold at {TS:g} s a sample), got {hold!r}")
    snr1 = _snr_pair(snr1)
    start = _start_date(start)
    root_seed(seed)  # refused before any file is written
    root = Path(out)
    if not root.parent.is_dir():
        raise InputError(f"out {root}: directory {root.parent} does not exist")
    root.mkdir(exist_ok=True)
    manifest = root / "MANIFEST.csv"
    if manifest.exists() and not force:
        raise InputError(f"{manifest} already exists; pass force=True to overwrite it")
    dates = [start + dt.timedelta(days=7 * k) for k in range(n_weeks)]
    drives = [f"drive-{d + 1:03d}" for d in range(n_drives)]
    cfg = {"spread": spread, "theta_spread": theta_spread, "max_rate": max_rate,
           "hold": float(hold), "snr1": snr1, "force": force}
    try:
        done = map_tasks(_one_drive, [(str(root), name, dates, cfg) for name in drives],
                         executor=executor, jobs=jobs, seed=seed)
    except FileExistsError as exc:
        raise InputError(f"{exc.filename} already exists; pass force=True to overwrite "
                         "it") from None
    _write_table(manifest, list(MANIFEST_COLUMNS), [r for d in done for r in d[0]], force)
    names = list(P_TRUE)
    _write_table(root / "TRUTH.csv", ["drive", "theta0", "rate_rad_per_year", *names],
                 [[n, repr(float(d[2])), repr(float(d[3])), *(repr(float(d[1][k])) for k in names)]
                  for n, d in zip(drives, done, strict=True)], force)
    return FleetTruth(manifest=manifest, drives=drives,
                      theta0=np.array([d[2] for d in done]),
                      rate=np.array([d[3] for d in done]),
                      params=[d[1] for d in done], dates=dates)
