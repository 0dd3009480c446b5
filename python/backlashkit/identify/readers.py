"""Read measured step-down experiments into :class:`~backlashkit.identify.Record` objects.

:func:`read_records` reads CSV text files (any of ``,``, ``;`` or tab as separator,
decimal point or decimal comma), MATLAB ``.mat`` files (v4/v5/v7 through
:func:`scipy.io.loadmat`; v7.3, which is HDF5, through the optional ``h5py``) and
NumPy ``.npz`` archives, and returns one :class:`~backlashkit.identify.Record` per
experiment found in the file.

Conventions
-----------
* **Columns.** Our names are ``t`` (s), ``torque`` (N m), ``w_motor`` and ``w_load``
  (rad/s, or rpm with ``speed_unit="rpm"``). ``columns`` maps any of them to the
  file's own names; names not mapped are looked up under our names.
* **Time.** Either a time column (default) or ``sample_time`` (the first sample at
  ``t = 0``), never both. The time must be finite and strictly increasing. Steps that
  differ from uniform by no more than the storage precision (1e-6 of the step, or a
  few float32 ulps for single-precision arrays) are snapped onto the exact uniform
  grid; anything else (jitter, a gap of missing samples) is an error unless
  ``resample="linear"``.
* **Missing values.** An empty CSV cell or ``nan`` is a missing sample: an error
  unless ``resample="linear"``, which bridges it by linear interpolation between the
  neighbouring valid samples (a channel missing its first or last sample is always
  an error: crop the record).
* **Resampling** (``resample="linear"``, only on request) puts every channel on the
  uniform grid ``t_0 + k Ts`` with ``Ts`` the median step of the file's time: speeds
  by linear interpolation, the torque as a zero-order hold (the value of the latest
  sample at or before each grid instant), so a torque step stays a step. It bridges
  at most :data:`MAX_BRIDGE` missing samples in a row (10): a longer gap would hide
  the impacts the identification looks for, so it stays an error.
* **Several records per file.** CSV: one record per file. ``.npz`` and ``.mat``:
  either variables with our (or mapped) names, one record; or the same names with a
  suffix ``_1``, ``_2``, ... (``w_motor_1``, ``w_load_1``, ``torque_1``, ...), one
  record per suffix in numerical order, the time being either suffixed too or one
  shared unsuffixed variable; or (``.mat`` only) struct variables, scalar or struct
  arrays, whose fields carry the names, one record per element (struct variables in
  name order). Each array must be a vector (MATLAB row or column vectors are
  flattened). Record names are the path, with ``:_1`` or ``:var(1)`` (1-based) added
  when the file holds several.

Every problem raises :class:`~backlashkit.errors.InputError` with a one-line message
naming the file, where (line, variable, sample) and what to do.
"""

from __future__ import annotations

import errno
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from .. import validate as v
from ..errors import InputError, Option
from ._csv_reader import (
    ANGLE_FIELDS,
    COLUMNS,
    DELIMITERS,
    FIELDS,
    RESAMPLE,
    SAMPLE_TIME,
    PathLike,
    _from_csv,
)
from ._mat_reader import _from_mat, _from_npz
from .record import Record

__all__ = ["ANGLE_FIELDS", "FIELDS", "SPEED_UNITS", "read_records", "read_torque"]


#: Accepted speed units and their factor to rad/s.
SPEED_UNITS = {"rad/s": 1.0, "rpm": 2.0 * math.pi / 60.0, "deg/s": math.pi / 180.0}

#: Longest run of missing samples (a time gap or NaN) that ``resample="linear"``
#: bridges; a longer one hides the drive's response (an impact lasts a few samples).
MAX_BRIDGE = 10

def read_records(
    path: PathLike,
    *,
    columns: Mapping[str, str] | None = None,
    sample_time: float | None = None,
    delimiter: str | None = None,
    decimal: str | None = None,
    speed_unit: str = "rad/s",
    resample: str | None = None,
    angles: bool = False,
    counts_per_rev: float | None = None,
) -> list[Record]:
    """Read the step-down experiments held in a measured file.

    Parameters
    ----------
    path : str or os.PathLike
        A ``.csv`` (or ``.txt``/``.tsv``/``.dat``: any other suffix is read as CSV
        text), ``.mat`` or ``.npz`` file.
    columns : mapping of str to str, optional
        Our names (``t``, ``torque``, ``w_motor``, ``w_load``) to the file's names of
        those columns or variables; unmapped ones keep our names.
    sample_time : float, optional
        Sample time in s, > 0, when the file has no time column (the first sample is
        at ``t = 0``). Give it or a time column, not both.
    delimiter : {",", ";", "\\t"}, optional
        CSV separator; default detected from the header line (``;`` if it holds one,
        else a tab if it holds one, else ``,``).
    decimal : {".", ","}, optional
        CSV decimal mark; default ``,`` if the separator is not ``,`` and a data
        cell holds a comma, else ``.``.
    speed_unit : {"rad/s", "rpm", "deg/s"}, optional
        Unit of the speeds in the file; rpm and deg/s are converted to rad/s (default
        rad/s).
    resample : {None, "linear"}, optional
        ``"linear"`` resamples onto a uniform grid at the median time step (speeds
        linearly, torque as a zero-order hold) and bridges runs of at most
        :data:`MAX_BRIDGE` missing samples; default None: non-uniform time, gaps and
        missing values are errors.
    angles : bool, optional
        The file holds the encoders' angles ``phi_motor``, ``phi_load`` in rad instead
        of the speeds (:meth:`Record.from_positions`; the joint estimator fits them).
    counts_per_rev : float, optional
        The file holds the angles ``phi_motor``, ``phi_load`` as encoder counts, with
        this many counts per revolution (implies ``angles``).

    Returns
    -------
    list of Record
        One record per experiment in the file (module docstring), in SI units.

    Raises
    ------
    InputError
        If an option is invalid, the file cannot be read, lacks a channel, or holds
        a value, time step or missing sample it cannot use; the one-line message
        names the file, the place and what to do.
    FileNotFoundError
        If the file does not exist.
    """
    if speed_unit not in SPEED_UNITS:
        raise InputError(f"speed_unit must be one of {', '.join(map(repr, SPEED_UNITS))}, "
                         f"got {speed_unit!r}")
    factor = SPEED_UNITS[speed_unit]
    if counts_per_rev is not None:
        v.positive("counts_per_rev", counts_per_rev)
        angles = True
    if angles:
        if speed_unit != "rad/s":
            raise InputError(Option("speed_unit", None), " does not apply to angles (in "
                             "rad, or in counts with ", Option("counts_per_rev", None),
                             "): leave it out, got ", Option("speed_unit", speed_unit))
        return [Record.from_positions(t, data["torque"], data["phi_motor"], data["phi_load"],
                                      counts_per_rev=counts_per_rev, name=rec_name)
                for rec_name, t, data in _read(path, ANGLE_FIELDS, columns, sample_time,
                                               delimiter, decimal, resample)]
    return [Record(t, data["torque"], data["w_motor"] * factor, data["w_load"] * factor,
                   name=rec_name)
            for rec_name, t, data in _read(path, FIELDS, columns, sample_time, delimiter,
                                           decimal, resample)]

def read_torque(
    path: PathLike,
    *,
    columns: Mapping[str, str] | None = None,
    sample_time: float | None = None,
    delimiter: str | None = None,
    decimal: str | None = None,
    resample: str | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Read a torque record (time and torque) with the readers of :func:`read_records`.

    Parameters
    ----------
    path : str or os.PathLike
        A ``.csv`` (any other suffix but ``.mat`` and ``.npz`` is read as CSV text),
        ``.mat`` or ``.npz`` file holding one record.
    columns : mapping of str to str, optional
        Our names ``t``, ``torque`` to the file's names (other columns are ignored).
    sample_time, delimiter, decimal, resample : optional
        As for :func:`read_records`.

    Returns
    -------
    t : numpy.ndarray
        Uniform, strictly increasing time grid in s.
    torque : numpy.ndarray
        Motor torque in N m, one per sample.

    Raises
    ------
    InputError
        As for :func:`read_records`, or if the file holds several records.
    FileNotFoundError
        If the file does not exist.
    """
    if columns is not None and isinstance(columns, Mapping):
        extra = [k for k in columns if k in ("w_motor", "w_load")]
        if extra:
            raise InputError(COLUMNS, f": {', '.join(extra)} is not read with the torque; "
                             "map t and torque only")
    recs = _read(path, ("t", "torque"), columns, sample_time, delimiter, decimal, resample,
                 keep_time=True)
    if len(recs) != 1:
        raise InputError(f"{path}: holds {len(recs)} records; give a file with one torque "
                         "record")
    _, t, data = recs[0]
    return t, data["torque"]

def _read(path, fields, columns, sample_time, delimiter, decimal, resample, *,
          keep_time=False):
    """(name, t, {channel: values}) of every record of a file, channels ``fields``
    (``keep_time``: a uniform time column as written, not recomputed from its ends)."""
    if not isinstance(path, (str, os.PathLike)):
        raise InputError(f"path must be a file name (str or pathlib.Path), got "
                         f"{type(path).__name__} {path!r}")
    name = str(path)
    mapping = _check_columns(columns, fields)
    if sample_time is not None:
        try:
            st = float(sample_time)
        except (TypeError, ValueError):
            st = math.nan
        if isinstance(sample_time, bool) or not math.isfinite(st) or not st > 0:
            raise InputError(f"sample_time must be a finite number > 0 (s), got {sample_time!r}")
        if columns is not None and "t" in columns:
            raise InputError(
                "give either ", SAMPLE_TIME, f" (got {sample_time!r}) or a time column (",
                Option("columns", f"t={columns['t']!r}",
                       python=f"columns['t'] = {columns['t']!r}"), "), not both"
            )
        sample_time = st
    if delimiter is not None and delimiter not in DELIMITERS:
        raise InputError(f"delimiter must be ',', ';' or a tab ('\\t'), got {delimiter!r}")
    if decimal is not None and decimal not in (".", ","):
        raise InputError(f"decimal must be '.' or ',', got {decimal!r}")
    if decimal == "," and delimiter == ",":
        raise InputError("decimal ',' needs another delimiter (';' or a tab), got delimiter ','")
    if resample not in (None, "linear"):
        raise InputError(f"resample must be None or 'linear', got {resample!r}")
    if not Path(path).is_file():
        if Path(path).is_dir():
            raise InputError(f"{name}: is a directory; give a .csv, .mat or .npz file")
        raise FileNotFoundError(errno.ENOENT, "no such file", name)
    suffix = Path(path).suffix.lower()
    need = [f for f in fields if not (f == "t" and sample_time is not None)]
    if suffix == ".npz":
        raws = _from_npz(name, mapping, need)
    elif suffix == ".mat":
        raws = _from_mat(name, mapping, need)
    else:
        raws = [_from_csv(name, mapping, need, delimiter, decimal)]
    if sample_time is not None:
        file_t = mapping["t"]
        for _, cols, _, _ in raws:
            if "t" in cols:
                raise InputError(
                    f"{name}: the file has a time column {file_t!r} and ",
                    Option("sample_time", sample_time, python=f"sample_time = {sample_time!r}"),
                    " was given; drop ", SAMPLE_TIME, " (or the column)"
                )
    return [(rec_name, *_build(rec_name, cols, label, precision, sample_time, resample, mapping,
                               keep_time))
            for rec_name, cols, label, precision in raws]

def _check_columns(columns: Mapping[str, str] | None,
                   fields: Sequence[str] = FIELDS) -> dict[str, str]:
    known = ANGLE_FIELDS if "phi_motor" in fields else FIELDS
    out = {f: f for f in known}
    if columns is None:
        return out
    if not isinstance(columns, Mapping):
        raise InputError(
            f"columns must be a mapping of our names {', '.join(known)} to the file's names, "
            f"got {type(columns).__name__}"
        )
    for key, value in columns.items():
        if key not in known:
            other = ("; the angles phi_motor, phi_load are read with angles or counts_per_rev"
                     if key in ANGLE_FIELDS else
                     "; the speeds are read without angles and counts_per_rev"
                     if key in FIELDS else "")
            raise InputError(COLUMNS, f": unknown key {key!r}; allowed keys: "
                             f"{', '.join(known)}{other}")
        if not isinstance(value, str) or not value.strip():
            raise InputError(f"columns[{key!r}] must be a non-empty string, got {value!r}")
        out[key] = value.strip()
    for a, b in ((a, b) for i, a in enumerate(fields) for b in fields[i + 1 :]):
        if out[a] == out[b]:
            raise InputError(
                COLUMNS, f": {a!r} and {b!r} both read the file's column {out[a]!r}; map "
                "each to its own column"
            )
    return out

def _build(rec_name, cols, label, precision, sample_time, resample,
           mapping, keep_time=False) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The uniform time grid and the channels on it (checked, resampled on request)."""
    n = {f: c.size for f, c in cols.items()}
    if len(set(n.values())) != 1:
        sizes = ", ".join(f"{mapping[f]}: {k}" for f, k in n.items())
        raise InputError(
            f"{rec_name}: the channels have different lengths ({sizes}); give every channel "
            "one value per sample"
        )
    size = next(iter(n.values()))
    if size < 3:
        raise InputError(f"{rec_name}: too few samples ({size}); at least 3 are needed")
    if sample_time is not None:
        t = np.arange(size) * sample_time
    else:
        t = cols["t"]
        bad = ~np.isfinite(t)
        if bad.any():
            i = int(np.argmax(bad))
            raise InputError(
                f"{rec_name}: {label(i)}: the time {mapping['t']!r} is missing or not finite "
                f"({t[i]}); a sample without a time cannot be placed: remove that row"
            )
    dt = np.diff(t)
    if not (dt > 0).all():
        i = int(np.argmax(~(dt > 0)))
        raise InputError(
            f"{rec_name}: {label(i + 1)}: the time {mapping['t']!r} = {float(t[i + 1])!r} does "
            f"not increase (previous {float(t[i])!r}); sort the samples and remove duplicates"
        )
    data = {f: x for f, x in cols.items() if f != "t"}
    for f, x in data.items():
        if np.isinf(x).any():
            i = int(np.argmax(np.isinf(x)))
            raise InputError(
                f"{rec_name}: {label(i)}: {mapping[f]!r} is infinite; fix the file"
            )
        miss = np.isnan(x)
        if not miss.any():
            continue
        i = int(np.argmax(miss))
        if resample is None:
            raise InputError(
                f"{rec_name}: {label(i)}: {mapping[f]!r} is missing (empty or NaN; "
                f"{int(miss.sum())} missing in all); fill the samples, crop the record, or pass ",
                RESAMPLE, " to bridge them by linear interpolation"
            )
        edges = np.diff(np.r_[0, miss.astype(np.int8), 0])
        starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        longest = int(np.argmax(stops - starts))
        if stops[longest] - starts[longest] > MAX_BRIDGE:
            raise InputError(
                f"{rec_name}: {label(int(starts[longest]))}: {mapping[f]!r} is missing for "
                f"{int(stops[longest] - starts[longest])} samples in a row, more than the "
                f"{MAX_BRIDGE} that ", RESAMPLE, " bridges; crop the record or split it "
                "at the gap"
            )
        if miss[0] or miss[-1]:
            j = 0 if miss[0] else size - 1
            raise InputError(
                f"{rec_name}: {label(j)}: {mapping[f]!r} is missing at the "
                f"{'start' if j == 0 else 'end'} of the record, where it cannot be "
                "interpolated; crop the record to the samples where every channel is known"
            )
    ts = float(np.median(dt))
    tol = max(precision, v.uniform_tolerance(t, ts))
    dev = np.abs(dt - ts)
    uniform = float(dev.max()) <= tol
    if uniform:
        # kept as written only at full precision: float32 times are snapped to the grid
        t_new = (t if keep_time and precision == 0.0
                 else t[0] + np.arange(size) * ((t[-1] - t[0]) / (size - 1)))
    elif resample is None:
        i = int(np.argmax(dev > tol))  # the first offending step
        kind = "a gap" if dt[i] > 1.5 * ts else "a non-uniform step"
        raise InputError(
            f"{rec_name}: {kind} in the time {mapping['t']!r} between {label(i)} and "
            f"{label(i + 1)}: {float(dt[i]):.6g} s against the median step {ts:.6g} s; pass ",
            RESAMPLE, " to resample onto a uniform grid, or fix the file"
        )
    else:
        i = int(np.argmax(dt))
        if dt[i] > (MAX_BRIDGE + 1) * ts:
            raise InputError(
                f"{rec_name}: a gap of {float(dt[i]):.6g} s in the time {mapping['t']!r} "
                f"between {label(i)} and {label(i + 1)} ({dt[i] / ts - 1:.0f} missing samples "
                f"at the median step {ts:.6g} s), more than the {MAX_BRIDGE} that ",
                RESAMPLE, " bridges; crop the record or split it at the gap"
            )
        m = int(math.floor((t[-1] - t[0]) / ts + 1e-9)) + 1
        t_new = t[0] + np.arange(m) * ts
    if uniform and resample is None:
        out = data
    else:
        out = {}
        for f, x in data.items():
            ok = ~np.isnan(x)
            if f == "torque":  # zero-order hold: the latest valid sample at or before
                tv, xv = t[ok], x[ok]
                k = np.searchsorted(tv, t_new + 1e-9 * ts, side="right") - 1
                out[f] = xv[np.clip(k, 0, xv.size - 1)]
            else:
                out[f] = np.interp(t_new, t[ok], x[ok])
    return t_new, out
