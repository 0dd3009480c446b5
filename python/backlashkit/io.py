"""Files read and written by the command-line tools.

**Drive file (TOML).** A ``[drive]`` table with exactly the keys of
:class:`~backlashkit.TwoMassDrive`, in SI units::

    [drive]
    J_M = 4.88e-3     # motor inertia, kg m^2 (> 0)
    J_L = 6.8e-2      # load inertia, kg m^2 (> 0)
    k_sh = 78.0       # shaft stiffness, N m/rad (> 0)
    f_M = 0.5e-2      # motor viscous friction, N m s/rad (>= 0)
    f_L = 0.5e-2      # load viscous friction, N m s/rad (>= 0)
    f_sh = 1.575e-2   # shaft damping, N m s/rad (>= 0)
    theta = 3.49e-2   # backlash HALF-width, rad (>= 0); total gap is 2 * theta

``theta`` may be left out when the backlash is what is to be identified
(``require_theta=False``). Besides ``[drive]`` the file may hold an optional
``[uncertainty]`` table of relative (fractional) uncertainties of the same
parameters, e.g. ``J_L = 0.1`` for +-10 %, read by :func:`read_uncertainty_toml`;
:func:`read_drive_toml` accepts and ignores it. Any other table or key is an error
(a misspelt key would otherwise be silently dropped).

**Data files (CSV).** Comma-separated (or semicolon- or tab-separated when the header
line holds no comma; the decimal mark is '.'), one header line of column names, then one
line of numbers per sample; blank lines and lines starting with ``#`` are skipped.
Columns are found by name (their order and any extra columns do not matter). A
column ``t`` holds the time in s and must be finite, strictly increasing and
uniform. :func:`write_csv` writes every float with :func:`repr`, the shortest text
that reads back to the same float, so a write/read round trip is exact.
"""

from __future__ import annotations

import csv
import io
import math
import os
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from . import _validate as v
from .errors import InputError
from .plants import TwoMassDrive

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

__all__ = [
    "DRIVE_KEYS",
    "load_toml",
    "read_csv_columns",
    "read_drive_toml",
    "read_torque_csv",
    "read_uncertainty_toml",
    "write_csv",
]

PathLike = str | os.PathLike[str]

#: Keys of the ``[drive]`` table, in file order.
DRIVE_KEYS = ("J_M", "J_L", "k_sh", "f_M", "f_L", "f_sh", "theta")
#: Top-level tables a drive file may hold.
TOP_LEVEL_TABLES = ("drive", "uncertainty")


def _fmt_keys(keys: Sequence[str]) -> str:
    return ", ".join(keys)


def load_toml(path: PathLike) -> dict[str, Any]:
    """Parse a TOML file, turning a syntax error into an :class:`InputError`.

    Parameters
    ----------
    path : str or os.PathLike
        The file.

    Returns
    -------
    dict
        The parsed document.

    Raises
    ------
    InputError
        If the file is not valid UTF-8 TOML; the message names the file and carries
        the parser's line and column.
    FileNotFoundError
        If the file does not exist.
    """
    with open(path, "rb") as fh:
        data = fh.read()
    try:
        return tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise InputError(
            f"{path}: not a UTF-8 text file ({exc.reason} at byte {exc.start})"
        ) from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML: {exc}") from None


def _check_top_level(doc: Mapping[str, Any], path: PathLike) -> None:
    unknown = [k for k in doc if k not in TOP_LEVEL_TABLES]
    if unknown:
        hint = ""
        if set(unknown) & set(DRIVE_KEYS):  # the parameters without their table header
            hint = " (the drive's parameters belong under a [drive] line)"
        raise InputError(
            f"{path}: unknown top-level key(s) {_fmt_keys(unknown)}; allowed tables: "
            f"[{'], ['.join(TOP_LEVEL_TABLES)}]{hint}"
        )


def _table(doc: Mapping[str, Any], name: str, path: PathLike, *, required: bool) -> dict | None:
    if name not in doc:
        if required:
            raise InputError(
                f"{path}: no [{name}] table; expected a [{name}] table with keys "
                f"{_fmt_keys(DRIVE_KEYS)}"
            )
        return None
    table = doc[name]
    if not isinstance(table, dict):
        raise InputError(f"{path}: {name} must be a table ([{name}]), got {table!r}")
    return table


def _number(path: PathLike, table: str, key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(
            f"{path}: [{table}] {key} must be a number, got {value!r} "
            f"({type(value).__name__})"
        )
    if not math.isfinite(value):
        raise InputError(f"{path}: [{table}] {key} must be finite, got {value!r}")
    return float(value)


def read_drive_toml(path: PathLike, *, require_theta: bool = True) -> TwoMassDrive:
    """Read a two-mass drive from the ``[drive]`` table of a TOML file.

    Parameters
    ----------
    path : str or os.PathLike
        The TOML file (format in the module docstring).
    require_theta : bool, optional
        If True (default) the backlash half-width ``theta`` must be given. If False it
        may be left out, and the drive's ``theta`` is then None (a prior for
        identification).

    Returns
    -------
    TwoMassDrive
        The drive.

    Raises
    ------
    InputError
        If the file does not parse, has no ``[drive]`` table, misses a key, has a key
        or table that is not allowed, a value that is not a finite number, a
        non-positive inertia or stiffness, or a negative friction, damping or backlash.
        The message names the file.
    FileNotFoundError
        If the file does not exist.
    """
    doc = load_toml(path)
    _check_top_level(doc, path)
    table = _table(doc, "drive", path, required=True)
    assert table is not None
    unknown = [k for k in table if k not in DRIVE_KEYS]
    if unknown:
        raise InputError(
            f"{path}: unknown key(s) {_fmt_keys(unknown)} in [drive]; allowed keys: "
            f"{_fmt_keys(DRIVE_KEYS)}"
        )
    required = DRIVE_KEYS if require_theta else DRIVE_KEYS[:-1]
    missing = [k for k in required if k not in table]
    if missing:
        hint = (
            " (theta is the backlash half-width in rad)"
            if missing == ["theta"]
            else ""
        )
        raise InputError(
            f"{path}: missing key(s) {_fmt_keys(missing)} in [drive]{hint}; required keys: "
            f"{_fmt_keys(required)}"
        )
    values = {k: _number(path, "drive", k, table[k]) for k in DRIVE_KEYS if k in table}
    try:
        return TwoMassDrive(**values)
    except InputError as exc:
        raise InputError(f"{path}: [drive] {exc}") from None


def read_uncertainty_toml(path: PathLike) -> dict[str, float]:
    """Read the optional ``[uncertainty]`` table of a drive file.

    Each entry is the relative (fractional) uncertainty of one linear drive parameter
    (``J_M``, ``J_L``, ``k_sh``, ``f_M``, ``f_L``, ``f_sh``; not ``theta``, which is
    estimated), e.g. ``J_L = 0.1`` for +-10 %. Parameters not listed are taken as exact.

    Parameters
    ----------
    path : str or os.PathLike
        The TOML file.

    Returns
    -------
    dict of str to float
        Relative uncertainty per parameter name (empty when the table is absent).

    Raises
    ------
    InputError
        If the file does not parse, the table holds a key that is not a linear drive
        parameter, or a value that is not a finite number >= 0.
    """
    doc = load_toml(path)
    _check_top_level(doc, path)
    table = _table(doc, "uncertainty", path, required=False)
    if table is None:
        return {}
    linear = DRIVE_KEYS[:-1]  # theta has no prior: it is what identification estimates
    if "theta" in table:
        raise InputError(
            f"{path}: [uncertainty] theta: the backlash is what identify estimates, without "
            f"a prior; remove it (list the linear parameters only: {_fmt_keys(linear)})"
        )
    unknown = [k for k in table if k not in linear]
    if unknown:
        raise InputError(
            f"{path}: unknown key(s) {_fmt_keys(unknown)} in [uncertainty]; allowed keys: "
            f"{_fmt_keys(linear)}"
        )
    out = {}
    for key, value in table.items():
        x = _number(path, "uncertainty", key, value)
        if x < 0:
            raise InputError(
                f"{path}: [uncertainty] {key} must be >= 0 (a relative uncertainty), got {value!r}"
            )
        out[key] = x
    return out


def read_csv_columns(
    path: PathLike,
    columns: Sequence[str],
    *,
    min_samples: int = 2,
) -> dict[str, np.ndarray]:
    """Read named numeric columns from a CSV file with a header line.

    Parameters
    ----------
    path : str or os.PathLike
        The file (format in the module docstring).
    columns : sequence of str
        Names of the columns to return; other columns of the file are not parsed. If
        ``"t"`` is among them it must be a uniform, strictly increasing time grid.
    min_samples : int, optional
        Fewest data lines accepted (default 2).

    Returns
    -------
    dict of str to numpy.ndarray
        One float64 array per requested column, in the order of ``columns``.

    Raises
    ------
    InputError
        If the file is empty, lacks a requested column, has a line with the wrong
        number of fields, a cell that is not a number (the message gives the line
        and the column), a NaN or infinite value, fewer than ``min_samples`` data
        lines, or a time column that is not strictly increasing and uniform.
    FileNotFoundError
        If the file does not exist.
    """
    name = str(path)
    numbers: list[int] = []
    rows: list[list[str]] = []
    try:
        with open(path, encoding="utf-8-sig", newline="") as fh:
            text = fh.read()
        # the separator of the header line: ',' unless it has none and ';' or a tab
        head = next((ln for ln in text.splitlines()
                     if ln.strip() and not ln.lstrip().startswith("#")), "")
        delimiter = next((d for d in (";", "\t") if "," not in head and d in head), ",")
        reader = csv.reader(io.StringIO(text), delimiter=delimiter)
        for row in reader:
            if not row or row[0].lstrip().startswith("#"):
                continue  # blank line or comment
            if len(row) == 1 and not row[0].strip():
                continue  # whitespace only
            numbers.append(reader.line_num)
            rows.append(row)
    except UnicodeDecodeError as exc:
        raise InputError(
            f"{name}: not a UTF-8 text file ({exc.reason} at byte {exc.start})"
        ) from None
    except csv.Error as exc:
        raise InputError(f"{name}: not a valid CSV file: {exc}") from None
    expected = ",".join(columns)
    if not rows:
        raise InputError(f"{name}: the file is empty; expected a header line '{expected}'")
    header_line, header = numbers[0], [cell.strip() for cell in rows[0]]
    seen = set()
    for col in header:
        if col in seen:
            raise InputError(
                f"{name}: line {header_line}: column '{col}' appears twice in the header"
            )
        seen.add(col)
    missing = [c for c in columns if c not in header]
    if missing:
        hint = (" (columns must be separated by commas, semicolons or tabs)"
                if len(header) == 1 else "")
        raise InputError(
            f"{name}: no column {', '.join(repr(c) for c in missing)} in the header "
            f"(line {header_line}: {','.join(header)!r}){hint}; expected columns '{expected}'"
        )
    data, lines = rows[1:], numbers[1:]
    if len(data) < min_samples:
        raise InputError(
            f"{name}: too few samples: {len(data)} data line(s), at least {min_samples} needed"
        )
    width = len(header)
    ragged = next((r for r, row in enumerate(data) if len(row) != width), None)
    if ragged is not None:
        raise InputError(
            f"{name}: line {lines[ragged]} has {len(data[ragged])} field(s) but the header "
            f"has {width}"
        )
    fields = list(zip(*data, strict=True))
    out = {c: _parse_column(name, c, fields[header.index(c)], lines) for c in columns}
    if "t" in out:
        _check_time(name, out["t"], lines)
    return out


def _parse_column(
    name: str, column: str, cells: Sequence[str], lines: Sequence[int]
) -> np.ndarray:
    try:  # fast path; any failure is located (and reported) by the slow one
        values = np.array(cells, dtype=np.float64)
    except ValueError:
        values = np.empty(len(cells))
        for r, cell in enumerate(cells):
            try:
                values[r] = float(cell)
            except ValueError:
                raise InputError(
                    f"{name}: line {lines[r]}, column '{column}': {cell!r} is not a number"
                ) from None
    bad = ~np.isfinite(values)
    if bad.any():
        r = int(np.argmax(bad))
        raise InputError(
            f"{name}: line {lines[r]}, column '{column}': value {cells[r]!r} is not finite; "
            "remove or fill NaN/inf samples"
        )
    return values


def _check_time(name: str, t: np.ndarray, lines: Sequence[int]) -> None:
    dt = np.diff(t)
    if not (dt > 0).all():
        i = int(np.argmax(~(dt > 0)))
        raise InputError(
            f"{name}: column 't' must be strictly increasing; line {lines[i + 1]} has "
            f"t = {float(t[i + 1])!r} after t = {float(t[i])!r} on line {lines[i]}"
        )
    ts = float((t[-1] - t[0]) / (t.size - 1))
    dev = np.abs(dt - ts)
    if dev.max() > v.uniform_tolerance(t, ts):
        i = int(np.argmax(dev))
        raise InputError(
            f"{name}: column 't' must be uniformly sampled; the step from line {lines[i]} to "
            f"line {lines[i + 1]} is {float(dt[i])!r} s but the mean step is {ts!r} s; resample "
            "the data onto a uniform grid first"
        )


def read_torque_csv(path: PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read a motor-torque record (columns ``t`` in s and ``torque`` in N m).

    Parameters
    ----------
    path : str or os.PathLike
        CSV file with a header line naming at least the columns ``t`` and ``torque``
        (other columns are ignored; an experiment file written by
        ``backlashkit simulate --experiment`` qualifies).

    Returns
    -------
    t : numpy.ndarray
        Uniform, strictly increasing time grid in s, at least 2 samples.
    torque : numpy.ndarray
        Motor torque in N m, one per sample.

    Raises
    ------
    InputError
        See :func:`read_csv_columns`.
    """
    cols = read_csv_columns(path, ("t", "torque"))
    return cols["t"], cols["torque"]


def write_csv(
    path: PathLike,
    columns: Mapping[str, Sequence[float] | np.ndarray],
    *,
    force: bool = False,
) -> None:
    """Write named columns to a CSV file at full float precision.

    Parameters
    ----------
    path : str or os.PathLike
        Output file. Its directory must exist.
    columns : mapping of str to array_like
        Column name to 1-D values, all of the same length, written in the mapping's
        order. Names must be non-empty and free of commas, quotes and line breaks.
    force : bool, optional
        Overwrite ``path`` if it exists (default False: refuse).

    Raises
    ------
    InputError
        If ``path`` exists and ``force`` is False, its directory does not exist, or
        the columns are malformed.

    Notes
    -----
    Every value is written with :func:`repr` of a Python float: the shortest
    decimal text that reads back to exactly the same float (``nan`` and ``inf`` are
    written as such).
    """
    if not columns:
        raise InputError("columns must hold at least one column, got none")
    arrays = []
    n = None
    for key, values in columns.items():
        if not isinstance(key, str) or not key or any(ch in key for ch in ',"\r\n'):
            raise InputError(
                f"column names must be non-empty strings without commas, quotes or line "
                f"breaks, got {key!r}"
            )
        try:
            arr = np.asarray(values, dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError(f"column {key!r} must hold real numbers") from None
        if arr.ndim != 1:
            raise InputError(f"column {key!r} must be 1-D, got shape {arr.shape}")
        if n is None:
            n = arr.size
        elif arr.size != n:
            raise InputError(f"all columns must have the same length; column {key!r} has "
                             f"{arr.size} values, the first column {n}")
        arrays.append(arr)
    target = Path(path)
    parent = target.parent
    if not parent.is_dir():
        raise InputError(f"cannot write {target}: directory {parent} does not exist")
    if target.is_dir():
        raise InputError(f"cannot write {target}: it is a directory")
    lines = [",".join(columns.keys())]
    rows = zip(*(a.tolist() for a in arrays), strict=True)
    lines.extend(",".join(map(repr, row)) for row in rows)
    text = "\n".join(lines) + "\n"
    try:
        with open(target, "w" if force else "x", encoding="utf-8", newline="") as fh:
            fh.write(text)
    except FileExistsError:
        raise InputError(
            f"{target} already exists; pass --force (force=True from Python) to overwrite it"
        ) from None


#: Figure formats of the CLI's ``--plot`` options (matplotlib's, by extension).
PLOT_SUFFIXES = (".png", ".svg", ".pdf", ".jpg", ".jpeg")


def check_plot_suffix(option: str, path: PathLike) -> None:
    """Refuse a figure file name whose extension names no :data:`PLOT_SUFFIXES` format.

    Parameters
    ----------
    option : str
        The option that gave the name, for the message (e.g. ``"--plot"``).
    path : str or os.PathLike
        The file name.

    Raises
    ------
    InputError
        If the extension is not one of :data:`PLOT_SUFFIXES` (any case).
    """
    if Path(path).suffix.lower() not in PLOT_SUFFIXES:
        raise InputError(f"{option} {path}: the file name must end in .png, .svg, .pdf or "
                         ".jpg (the figure's format)")


def check_writable(path: PathLike, what: str, *, directory: bool = False) -> None:
    """Refuse, before any computation, an output the system will not let us write.

    A file that does not exist is created and removed again; one that exists is opened
    for appending (its content stays); for a directory, a probe file is created in it or
    in its nearest existing parent (where it would be created). Permission bits alone
    do not tell (a root user may not create files under ``/proc`` either).

    Parameters
    ----------
    path : str or os.PathLike
        The output file or directory.
    what : str
        How the message names it (e.g. ``"--out"``).
    directory : bool, optional
        ``path`` is a directory to write files into.

    Raises
    ------
    InputError
        If the system refuses to write there (the message gives its reason).
    """
    import tempfile

    target = Path(path)
    if target.is_symlink() and not target.exists():
        raise InputError(f"cannot write {what} {target}: a broken symbolic link (to "
                         f"{os.readlink(target)}); remove it or give another name")
    try:
        if directory:
            home = next((p for p in (target, *target.parents) if p.exists()), Path("."))
            if home.is_dir():  # else the writer says what is in the way
                with tempfile.TemporaryFile(dir=home):
                    pass
        elif target.exists():
            if target.is_file():  # not a FIFO or a device: opening those may block
                with open(target, "a", encoding="utf-8"):
                    pass
        else:
            with open(target, "x", encoding="utf-8"):
                pass
            target.unlink()
    except OSError as exc:
        raise InputError(f"cannot write {what} {target}: {exc.strerror or exc}") from None
