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

import csv
import errno
import io
import math
import os
import re
import warnings
import zipfile
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .. import validate as v
from ..errors import InputError
from .record import Record

__all__ = ["FIELDS", "read_records", "read_torque"]

PathLike = str | os.PathLike[str]

#: Our names of a record's channels, in order.
FIELDS = ("t", "torque", "w_motor", "w_load")
#: Accepted speed units and their factor to rad/s.
SPEED_UNITS = {"rad/s": 1.0, "rpm": 2.0 * math.pi / 60.0}
DELIMITERS = (",", ";", "\t")
#: Longest run of missing samples (a time gap or NaN) that ``resample="linear"``
#: bridges; a longer one hides the drive's response (an impact lasts a few samples).
MAX_BRIDGE = 10
_SUFFIX = re.compile(r"^(.*)_(\d+)$")

# (name of the record, raw channels (t may be absent), label of sample i, time precision)
_Raw = tuple[str, dict[str, np.ndarray], Callable[[int], str], float]


def read_records(
    path: PathLike,
    *,
    columns: Mapping[str, str] | None = None,
    sample_time: float | None = None,
    delimiter: str | None = None,
    decimal: str | None = None,
    speed_unit: str = "rad/s",
    resample: str | None = None,
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
    speed_unit : {"rad/s", "rpm"}, optional
        Unit of the speeds in the file; rpm are converted to rad/s (default rad/s).
    resample : {None, "linear"}, optional
        ``"linear"`` resamples onto a uniform grid at the median time step (speeds
        linearly, torque as a zero-order hold) and bridges runs of at most
        :data:`MAX_BRIDGE` missing samples; default None: non-uniform time, gaps and
        missing values are errors.

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
        raise InputError(f"speed_unit must be 'rad/s' or 'rpm', got {speed_unit!r}")
    factor = SPEED_UNITS[speed_unit]
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
            raise InputError(f"columns: {', '.join(extra)} is not read with the torque; map "
                             "t and torque only")
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
                f"give either sample_time (got {sample_time!r}) or a time column "
                f"(columns['t'] = {columns['t']!r}), not both"
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
                    f"{name}: the file has a time column {file_t!r} and sample_time = "
                    f"{sample_time!r} was given; drop sample_time (or the column)"
                )
    return [(rec_name, *_build(rec_name, cols, label, precision, sample_time, resample, mapping,
                               keep_time))
            for rec_name, cols, label, precision in raws]


def _check_columns(columns: Mapping[str, str] | None,
                   fields: Sequence[str] = FIELDS) -> dict[str, str]:
    out = {f: f for f in FIELDS}
    if columns is None:
        return out
    if not isinstance(columns, Mapping):
        raise InputError(
            f"columns must be a mapping of our names {', '.join(FIELDS)} to the file's names, "
            f"got {type(columns).__name__}"
        )
    for key, value in columns.items():
        if key not in FIELDS:
            raise InputError(
                f"columns: unknown key {key!r}; allowed keys: {', '.join(FIELDS)}"
            )
        if not isinstance(value, str) or not value.strip():
            raise InputError(f"columns[{key!r}] must be a non-empty string, got {value!r}")
        out[key] = value.strip()
    for a, b in ((a, b) for i, a in enumerate(fields) for b in fields[i + 1 :]):
        if out[a] == out[b]:
            raise InputError(
                f"columns: {a!r} and {b!r} both read the file's column {out[a]!r}; map "
                "each to its own column"
            )
    return out


# --- CSV -------------------------------------------------------------------------


def _from_csv(name: str, mapping: dict[str, str], need: list[str], delimiter, decimal) -> _Raw:
    with open(name, "rb") as fh:
        head = fh.read(2)
    # Excel's "Unicode text" export is UTF-16 with a byte-order mark
    encoding = "utf-16" if head in (b"\xff\xfe", b"\xfe\xff") else "utf-8-sig"
    if encoding != "utf-16" and b"\x00" in head:
        raise InputError(
            f"{name}: holds NUL bytes: UTF-16 text without a byte-order mark? save it as "
            "UTF-8 CSV (or UTF-16 with its mark)"
        )
    try:
        with open(name, encoding=encoding, newline="") as fh:
            text = fh.read()
    except UnicodeDecodeError as exc:
        raise InputError(
            f"{name}: not a UTF-8 text file ({exc.reason} at byte {exc.start}); save it as "
            "UTF-8 CSV"
        ) from None
    fast = _fast_csv(name, text, mapping, need, delimiter, decimal)
    if fast is not None:
        return fast
    lines = [
        (k + 1, line)
        for k, line in enumerate(text.splitlines())
        if line.strip() and not line.lstrip().startswith("#")
    ]
    if not lines:
        raise InputError(f"{name}: the file is empty; expected a header line naming the columns")
    header_no, header_text = lines[0]
    delimiter = delimiter or _sniff_delimiter(header_text)
    try:
        reader = csv.reader(io.StringIO("\n".join(line for _, line in lines)),
                            delimiter=delimiter)
        rows = list(reader)
    except csv.Error as exc:
        raise InputError(f"{name}: not a valid CSV file: {exc}") from None
    if len(rows) != len(lines):  # quoted line breaks: not a table of numbers
        raise InputError(f"{name}: a quoted field spans several lines; remove the line breaks")
    header = [c.strip() for c in rows[0]]
    data, numbers = rows[1:], [n for n, _ in lines[1:]]
    if decimal is None:
        decimal = "," if delimiter != "," and any("," in c for row in data for c in row) else "."
    if decimal == "," and delimiter == ",":
        raise InputError(f"{name}: decimal ',' needs another delimiter (';' or a tab)")
    if all(_is_number(c, decimal) for c in header):
        raise InputError(
            f"{name}: line {header_no} holds numbers, not column names; add a header line "
            f"naming the columns (e.g. {delimiter.join(mapping[f] for f in need)!r})"
        )
    for col in header:
        if header.count(col) > 1:
            raise InputError(f"{name}: line {header_no}: column {col!r} appears twice")
    missing = [mapping[f] for f in need if mapping[f] not in header]
    others = [d for d in DELIMITERS if d != delimiter and len(header) == 1 and d in header[0]]
    if missing and others:  # one column holding another separator: the wrong delimiter
        sep = {"\t": "tab", ",": "','", ";": "';'"}
        raise InputError(
            f"{name}: the header (line {header_no}) is one column {header[0]!r} with "
            f"{sep[others[0]]} in it: the columns are separated by {sep[others[0]]}, not "
            f"{sep[delimiter]}; pass delimiter={others[0]!r}"
        )
    if missing:
        sep = {"\t": "tab", ",": "','", ";": "';'"}[delimiter]
        raise InputError(
            f"{name}: no column {', '.join(map(repr, missing))} in the header (line "
            f"{header_no}, separator {sep}: {header!r}); map the file's names with "
            "columns={" + ", ".join(f"{f!r}: ..." for f in FIELDS if f in need or f == "t")
            + "}"
            + (" or pass sample_time= if there is no time column" if "t" in need else "")
        )
    if "t" not in need and mapping["t"] in header:
        need = ["t", *need]  # read it so that the conflict with sample_time is reported
    width = len(header)
    for r, row in enumerate(data):
        if len(row) != width:
            raise InputError(
                f"{name}: line {numbers[r]} has {len(row)} field(s) but the header has {width}; "
                f"check the separator (delimiter={delimiter!r}) and the decimal mark"
            )
    cols = {}
    for f in need:
        j = header.index(mapping[f])
        cols[f] = _parse_cells(name, mapping[f], [row[j] for row in data], numbers, decimal)
    return name, cols, lambda i: f"line {numbers[i]}", 0.0


def _sniff_delimiter(header: str) -> str:
    """``;`` if the header line holds one, else a tab if it holds one, else ``,``."""
    return next((d for d in (";", "\t") if d in header), ",")


def _fast_csv(name: str, text: str, mapping: dict[str, str], need: list[str], delimiter,
              decimal) -> _Raw | None:
    """A well-formed numeric table read by :func:`numpy.loadtxt` (C speed), or None.

    None sends the file to the line-by-line reader below, which reads the same files
    the same way and names the line and column of whatever is wrong; this path only
    takes files with nothing to report (plain header, no comment after it, every cell
    a finite number or ``nan``, the same number of fields on every line).
    """
    pos, header_no = 0, 0
    while pos < len(text):  # the header: the first line neither blank nor a comment
        end = text.find("\n", pos)
        end = len(text) if end < 0 else end + 1
        header_no += 1
        line = text[pos:end].strip()
        pos = end
        if line and not line.startswith("#"):
            break
    else:
        return None
    delimiter = delimiter or _sniff_delimiter(line)
    header = [c.strip() for c in line.split(delimiter)]
    body = text[pos:]
    if decimal is None:
        decimal = "," if delimiter != "," and "," in body else "."
    if ('"' in line or (decimal == "," and delimiter == ",") or len(set(header)) < len(header)
            or any(mapping[f] not in header for f in need)):
        return None
    if all(_is_number(c, decimal) for c in header):
        return None
    if "_" in body or (decimal == "," and "." in body):
        return None  # cells float() would misread: the checked reader says which
    try:
        with warnings.catch_warnings():  # an empty body: the checked reader says so
            warnings.simplefilter("ignore", UserWarning)
            table = np.loadtxt(io.StringIO(body.replace(",", ".") if decimal == "," else body),
                               delimiter=delimiter, comments=None, ndmin=2, dtype=float)
    except ValueError:
        return None
    if table.shape[0] == 0 or table.shape[1] != len(header) or np.isinf(table).any():
        return None
    if "t" not in need and mapping["t"] in header:
        need = ["t", *need]  # read it so that the conflict with sample_time is reported
    cols = {f: np.ascontiguousarray(table[:, header.index(mapping[f])]) for f in need}
    numbers: list[int] = []

    def label(i: int) -> str:  # line numbers only when a message needs one
        if not numbers:  # blank lines are skipped by loadtxt, comments are not taken
            numbers.extend(header_no + k + 1 for k, ln in enumerate(body.splitlines())
                           if ln.strip())
        return f"line {numbers[i]}"

    return name, cols, label, 0.0


#: A date (2024-01-31, 31/01/2024, 31.01.2024) or a clock time (12:30:05).
_DATE_TIME = re.compile(r"\d{1,4}[-/.]\d{1,2}[-/.]\d{1,4}|\d{1,2}:\d{2}")
_MISSING = {"", "nan", "na", "n/a", "null"}


def _is_number(cell: str, decimal: str) -> bool:
    try:
        float(cell.strip().replace(decimal, ".") if decimal == "," else cell.strip())
    except ValueError:
        return False
    return True


def _parse_cells(name, column, cells, numbers, decimal) -> np.ndarray:
    out = np.empty(len(cells))
    for r, raw in enumerate(cells):
        cell = raw.strip()
        if cell.lower() in _MISSING:
            out[r] = np.nan
            continue
        bad = None
        if "_" in cell:
            bad = "has an underscore, which is no number format of a measurement file"
        elif decimal == "," and "." in cell:
            bad = ("has a '.' but the decimal mark is ','; thousands separators are not "
                   "read: remove them (or pass decimal='.' if '.' is the decimal mark)")
        if bad is not None:
            raise InputError(f"{name}: line {numbers[r]}, column {column!r}: {raw!r} {bad}")
        if decimal == ",":
            cell = cell.replace(",", ".")
        try:
            out[r] = float(cell)
        except ValueError:
            hint = (
                "; for decimal commas pass decimal=',' with delimiter ';' or a tab"
                if "," in raw and decimal == "."
                else ""
            )
            if _DATE_TIME.search(cell):
                hint = ("; a date or clock time is no time in s: convert the column to "
                        "seconds, or remove it and pass sample_time=")
            raise InputError(
                f"{name}: line {numbers[r]}, column {column!r}: {raw!r} is not a number{hint}"
            ) from None
        if math.isinf(out[r]):
            raise InputError(
                f"{name}: line {numbers[r]}, column {column!r}: {raw!r} is infinite; fix the file"
            )
    return out


# --- NPZ and MAT -----------------------------------------------------------------


def _vector(name: str, var: str, value: Any) -> np.ndarray:
    if hasattr(value, "toarray"):  # a scipy.sparse matrix (MATLAB's sparse)
        raise InputError(f"{name}: variable {var!r} is a sparse matrix; save it as a full "
                         "numeric vector (full(x) in MATLAB)")
    arr = np.asarray(value)
    if arr.dtype == object:
        raise InputError(f"{name}: variable {var!r} holds a cell array or other objects, not "
                         "numbers; save it as a numeric vector")
    if arr.dtype == bool:  # a MATLAB logical: a mask or a flag saved by mistake
        raise InputError(f"{name}: variable {var!r} holds true/false values, not "
                         "measurements; save the signal itself (double(x) in MATLAB if "
                         "0 and 1 are meant)")
    if not np.issubdtype(arr.dtype, np.number) or np.iscomplexobj(arr):
        raise InputError(f"{name}: variable {var!r} must hold real numbers, got {arr.dtype}")
    if arr.ndim != 1:
        if sum(s > 1 for s in arr.shape) > 1:
            raise InputError(
                f"{name}: variable {var!r} must be a vector, got shape {arr.shape}; store one "
                "vector per channel (or suffix _1, _2, ... per experiment)"
            )
        arr = arr.reshape(-1)
    return arr


def _precision(arr: np.ndarray) -> float:
    if arr.dtype == np.float32:
        return 4.0 * float(np.finfo(np.float32).eps) * float(np.max(np.abs(arr), initial=0.0))
    return 0.0


def _sample_label(var: str) -> Callable[[int], str]:
    return lambda i: f"sample {i} (0-based) of {var!r}"


def _from_variables(name: str, variables: Mapping[str, Any], mapping: dict[str, str],
                    need: list[str], what: str) -> list[_Raw]:
    """Records from a flat set of named arrays (plain or suffixed names)."""
    want = {mapping[f]: f for f in FIELDS}
    # numbered channels (a shared plain time is allowed beside them)
    suffixed = sorted(v for v in variables if (m := _SUFFIX.match(v))
                      and m.group(1) in want and m.group(1) != mapping["t"])
    if all(mapping[f] in variables for f in need):
        if suffixed:  # one plain record and numbered ones: which did the user mean?
            raise InputError(
                f"{name}: holds both plain {what}s ({', '.join(mapping[f] for f in need)}) "
                f"and numbered ones ({', '.join(map(repr, suffixed[:4]))}"
                f"{', ...' if len(suffixed) > 4 else ''}); keep one naming scheme"
            )
        present = [f for f in FIELDS if mapping[f] in variables]
        cols = {f: _vector(name, mapping[f], variables[mapping[f]]) for f in present}
        prec = _precision(cols["t"]) if "t" in cols else 0.0
        var_t = mapping["t"]
        return [(name, {f: c.astype(float) for f, c in cols.items()}, _sample_label(var_t),
                 prec)]
    groups: dict[int, dict[str, str]] = {}
    for var in variables:
        m = _SUFFIX.match(var)
        if m and m.group(1) in want:
            groups.setdefault(int(m.group(2)), {})[want[m.group(1)]] = var
    if not groups:
        missing = [mapping[f] for f in need if mapping[f] not in variables]
        raise InputError(
            f"{name}: no {what} {', '.join(map(repr, missing))} (found: "
            f"{', '.join(map(repr, sorted(variables))) or 'none'}); name them "
            f"{', '.join(mapping[f] for f in need)} (or with suffixes _1, _2, ...), or map "
            "them with columns={...}"
            + (" (or pass sample_time= if there is no time)" if "t" in need else "")
        )
    out = []
    for k in sorted(groups):
        g = groups[k]
        if "t" not in g and mapping["t"] in variables:
            g["t"] = mapping["t"]
        missing = [f"{mapping[f]}_{k}" for f in need if f not in g]
        if missing:
            raise InputError(
                f"{name}: experiment _{k} has no {what} {', '.join(map(repr, missing))}; every "
                f"suffix needs {', '.join(mapping[f] for f in need if f != 't')} (and a time "
                f"{mapping['t']}_{k} or a shared {mapping['t']})"
            )
        cols = {f: _vector(name, g[f], variables[g[f]]) for f in g}
        prec = _precision(cols["t"]) if "t" in cols else 0.0
        out.append((f"{name}:_{k}", {f: c.astype(float) for f, c in cols.items()},
                    _sample_label(g.get("t", f"w_motor_{k}")), prec))
    return out


def _from_npz(name: str, mapping: dict[str, str], need: list[str]) -> list[_Raw]:
    if not zipfile.is_zipfile(name):  # else NumPy would talk of unpickling it
        raise InputError(f"{name}: not a NumPy .npz archive (no zip file); save the arrays "
                         "with numpy.savez, or give the file its real extension")
    try:
        with np.load(name, allow_pickle=False) as npz:
            variables = {k: npz[k] for k in npz.files}
    except ValueError as exc:
        raise InputError(
            f"{name}: cannot read the .npz archive ({exc}); save plain numeric arrays with "
            "numpy.savez"
        ) from None
    except (OSError, EOFError) as exc:
        raise InputError(f"{name}: not a NumPy .npz archive ({exc})") from None
    return _from_variables(name, variables, mapping, need, "array")


def _is_mat73(name: str) -> bool:
    with open(name, "rb") as fh:
        head = fh.read(520)
    return b"MATLAB 7.3" in head[:128] or head[512:520] == b"\x89HDF\r\n\x1a\n" or (
        head[:8] == b"\x89HDF\r\n\x1a\n"
    )


def _from_mat(name: str, mapping: dict[str, str], need: list[str]) -> list[_Raw]:
    if _is_mat73(name):
        return _from_mat73(name, mapping, need)
    from scipy import io as sio

    try:
        raw = sio.loadmat(name, squeeze_me=False, struct_as_record=True)
    except NotImplementedError:  # v7.3 not recognised by the header check
        return _from_mat73(name, mapping, need)
    except Exception as exc:  # scipy raises many types for a corrupt file
        raise InputError(
            f"{name}: not a readable MATLAB .mat file ({type(exc).__name__}: {exc}); save it "
            "with MATLAB's save (-v7 or -v7.3)"
        ) from None
    variables = {k: v for k, v in raw.items() if not k.startswith("__")}
    flat = {k: v for k, v in variables.items() if v.dtype.names is None}
    structs = {k: v for k, v in variables.items() if v.dtype.names is not None}
    fieldset = {mapping[f] for f in need}
    usable = {k: v for k, v in structs.items() if fieldset <= set(v.dtype.names)}
    if usable and not all(mapping[f] in flat for f in need):
        out = []
        for var in sorted(usable):
            arr = usable[var].reshape(-1, order="F")
            for i, elem in enumerate(arr):
                fields = {fn: elem[fn] for fn in arr.dtype.names}
                rec_name = f"{name}:{var}({i + 1})" if arr.size > 1 or len(usable) > 1 else name
                recs = _from_variables(rec_name, fields, mapping, need, f"field of {var!r}")
                out.extend(recs)
        return out
    _refuse_partial_struct(name, {k: set(v.dtype.names) for k, v in structs.items()}, flat,
                           mapping, need)
    return _from_variables(name, flat, mapping, need, "variable")


def _refuse_partial_struct(name: str, structs: dict[str, set[str]], flat, mapping,
                           need: list[str]) -> None:
    """A struct holding some of the channels but not all: name the missing fields."""
    if all(mapping[f] in flat for f in need):
        return
    for var, fields in sorted(structs.items()):
        have = [mapping[f] for f in need if mapping[f] in fields]
        if have:
            missing = [mapping[f] for f in need if mapping[f] not in fields]
            raise InputError(
                f"{name}: struct {var!r} has no field {', '.join(map(repr, missing))} (it has "
                f"{', '.join(map(repr, sorted(fields)))}); add the channel or map the names "
                "with columns={...}"
            )


def _from_mat73(name: str, mapping: dict[str, str], need: list[str]) -> list[_Raw]:
    try:
        import h5py
    except ImportError:
        raise InputError(
            f"{name}: a MATLAB v7.3 (HDF5) file needs the optional package h5py; install it "
            "(pip install h5py) or save the file with save(..., '-v7')"
        ) from None
    try:
        fh = h5py.File(name, "r")
    except OSError as exc:
        raise InputError(f"{name}: not a readable MATLAB v7.3 (HDF5) file ({exc})") from None
    with fh:
        flat: dict[str, np.ndarray] = {}
        odd: dict[str, str] = {}  # datasets that are no real numeric arrays -> what they are
        groups: dict[str, set[str]] = {}
        structs: dict[str, list[dict[str, np.ndarray]]] = {}
        for key, obj in fh.items():
            if key.startswith("#"):
                continue  # MATLAB's #refs# group
            if isinstance(obj, h5py.Dataset):
                if obj.dtype.kind in "iuf":
                    flat[key] = obj[()]
                elif obj.dtype.kind == "c" or (obj.dtype.names is not None
                                               and {"real", "imag"} <= set(obj.dtype.names)):
                    odd[key] = "complex numbers"  # MATLAB stores them as (real, imag)
                else:
                    odd[key] = ("a cell array" if obj.dtype == h5py.ref_dtype
                                else f"data of type {obj.dtype}")
            elif isinstance(obj, h5py.Group):
                groups[key] = set(obj.keys())
                elems = _h5_struct(fh, obj)
                if elems:
                    structs[key] = elems
    fieldset = {mapping[f] for f in need}
    usable = {k: e for k, e in structs.items() if all(fieldset <= set(x) for x in e)}
    if usable and not all(mapping[f] in flat for f in need):
        out = []
        for var in sorted(usable):
            elems = usable[var]
            for i, fields in enumerate(elems):
                rec_name = f"{name}:{var}({i + 1})" if len(elems) > 1 or len(usable) > 1 else name
                out.extend(_from_variables(rec_name, fields, mapping, need, f"field of {var!r}"))
        return out
    for f in need:
        if mapping[f] not in flat and mapping[f] in odd:
            raise InputError(
                f"{name}: variable {mapping[f]!r} holds {odd[mapping[f]]}, not real numbers; "
                "save it as a real numeric array"
            )
    _refuse_partial_struct(name, groups, flat, mapping, need)
    return _from_variables(name, flat, mapping, need, "variable")


def _h5_struct(fh, group) -> list[dict[str, np.ndarray]]:
    """Elements of a v7.3 struct: fields are datasets (scalar) or references (array)."""
    import h5py

    fields = {k: d for k, d in group.items() if isinstance(d, h5py.Dataset)}
    if not fields:
        return []
    if all(d.dtype.kind in "iuf" for d in fields.values()):
        return [{k: d[()] for k, d in fields.items()}]
    if all(d.dtype == h5py.ref_dtype for d in fields.values()):
        refs = {k: np.asarray(d[()]).reshape(-1, order="F") for k, d in fields.items()}
        n = {r.size for r in refs.values()}
        if len(n) != 1:
            return []
        return [{k: fh[r[i]][()] for k, r in refs.items()} for i in range(n.pop())]
    return []


# --- checks, snapping and resampling ----------------------------------------------


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
                f"{int(miss.sum())} missing in all); fill the samples, crop the record, or pass "
                "resample='linear' to bridge them by linear interpolation"
            )
        edges = np.diff(np.r_[0, miss.astype(np.int8), 0])
        starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        longest = int(np.argmax(stops - starts))
        if stops[longest] - starts[longest] > MAX_BRIDGE:
            raise InputError(
                f"{rec_name}: {label(int(starts[longest]))}: {mapping[f]!r} is missing for "
                f"{int(stops[longest] - starts[longest])} samples in a row, more than the "
                f"{MAX_BRIDGE} that resample='linear' bridges; crop the record or split it "
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
            f"{label(i + 1)}: {float(dt[i]):.6g} s against the median step {ts:.6g} s; pass "
            "resample='linear' to resample onto a uniform grid, or fix the file"
        )
    else:
        i = int(np.argmax(dt))
        if dt[i] > (MAX_BRIDGE + 1) * ts:
            raise InputError(
                f"{rec_name}: a gap of {float(dt[i]):.6g} s in the time {mapping['t']!r} "
                f"between {label(i)} and {label(i + 1)} ({dt[i] / ts - 1:.0f} missing samples "
                f"at the median step {ts:.6g} s), more than the {MAX_BRIDGE} that "
                "resample='linear' bridges; crop the record or split it at the gap"
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
