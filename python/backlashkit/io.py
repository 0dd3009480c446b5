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
(``require_theta=False``). Optional friction keys: ``fc_M``, ``fc_L`` (Coulomb
friction torques, N m, >= 0) and ``fs_M``, ``fs_L`` (breakaway torques, N m, >= the
Coulomb torque; default equal to it). An optional ``[actuator]`` table with ``tau_i``
(current-loop time constant, s, >= 0) is read by :func:`read_actuator_toml`.
Besides ``[drive]`` the file may hold an optional
``[uncertainty]`` table of relative (fractional) uncertainties of the linear
parameters and the Coulomb torques, e.g. ``J_L = 0.1`` for +-10 %, read by
:func:`read_uncertainty_toml`;
:func:`read_drive_toml` accepts and ignores it. Any other table or key is an error
(a misspelt key would otherwise be silently dropped).

**Data files (CSV).** :func:`write_csv` writes one header line of column names, then
one line per sample, every float with :func:`repr`, the shortest text that reads back to
the same float, so a write/read round trip is exact. Measured files are read by
:mod:`backlashkit.identify.readers`.
"""

from __future__ import annotations

import math
import os
import sys
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .errors import InputError
from .plants import TwoMassDrive
from .validate import degrees_note

if TYPE_CHECKING:
    from .actuator import CurrentLoop

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

__all__ = [
    "DRIVE_KEYS",
    "did_you_mean",
    "load_toml",
    "read_actuator_toml",
    "read_drive_toml",
    "read_uncertainty_toml",
    "write_csv",
]

PathLike = str | os.PathLike[str]

#: Keys of the ``[drive]`` table, in file order.
DRIVE_KEYS = ("J_M", "J_L", "k_sh", "f_M", "f_L", "f_sh", "theta")
#: Optional friction keys of the ``[drive]`` table.
FRICTION_KEYS = ("fc_M", "fc_L", "fs_M", "fs_L")
#: The friction keys an ``[uncertainty]`` table may give: the Coulomb torques, which
#: the joint estimator fits (the breakaway torque is tied to them).
UNCERTAIN_FRICTION_KEYS = ("fc_M", "fc_L")
#: The terms' keys an ``[uncertainty]`` table may give: the Coulomb torques, and a
#: known current loop's time constant (about the ``[actuator]`` table's).
UNCERTAIN_TERM_KEYS = (*UNCERTAIN_FRICTION_KEYS, "tau_i")
#: Keys of the optional ``[actuator]`` table.
ACTUATOR_KEYS = ("tau_i",)
#: Top-level tables a drive file may hold.
TOP_LEVEL_TABLES = ("drive", "uncertainty", "actuator")


#: How alike (difflib's ratio, case ignored) a misspelt key and an allowed one must be
#: for "did you mean": 0.7 takes a swap (``k_hs`` for ``k_sh``, 0.75), a missing
#: underscore (``JL`` for ``J_L``, 0.8) or a wrong case (``J_m``, 1.0), but guesses
#: nothing for ``J_X`` (0.67 to any of ``J_M``, ``J_L``: either could be meant).
SUGGEST_CUTOFF = 0.7


def _fmt_keys(keys: Sequence[str]) -> str:
    return ", ".join(keys)


def did_you_mean(unknown: Sequence[str], allowed: Sequence[str], *,
                 brackets: bool = False) -> str:
    """`` (did you mean k_sh?)`` for the unknown keys that look like an allowed one.

    Parameters
    ----------
    unknown : sequence of str
        The keys given that are not allowed.
    allowed : sequence of str
        The keys allowed (matched without regard to case).
    brackets : bool, optional
        Say the guesses as tables, ``[drive]`` (default False).

    Returns
    -------
    str
        The suggestion, with a leading space; empty where none is close.
    """
    import difflib

    by_lower = {a.lower(): a for a in allowed}
    guesses = []
    for key in unknown:
        close = difflib.get_close_matches(key.lower(), list(by_lower), n=1,
                                          cutoff=SUGGEST_CUTOFF)
        if close:
            name = by_lower[close[0]]
            guesses.append(f"[{name}]" if brackets else name)
    if not guesses:
        return ""
    return f" (did you mean {' or '.join(dict.fromkeys(guesses))}?)"


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
        If the file is a directory or not valid UTF-8 TOML; the message names the file
        and carries the parser's line and column.
    FileNotFoundError
        If the file does not exist.
    """
    if Path(path).is_dir():
        raise InputError(f"{path}: is a directory; give a TOML file")
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
        header = ""
        if set(unknown) & set(DRIVE_KEYS):  # the parameters without their table header
            header = " (the drive's parameters belong under a [drive] line)"
        raise InputError(
            f"{path}: unknown top-level key(s) {_fmt_keys(unknown)}"
            f"{'' if header else did_you_mean(unknown, TOP_LEVEL_TABLES, brackets=True)}; "
            f"allowed tables: [{'], ['.join(TOP_LEVEL_TABLES)}]{header}"
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
    unknown = [k for k in table if k not in DRIVE_KEYS + FRICTION_KEYS]
    if unknown:
        raise InputError(
            f"{path}: unknown key(s) {_fmt_keys(unknown)} in [drive]"
            f"{did_you_mean(unknown, DRIVE_KEYS + FRICTION_KEYS)}; allowed keys: "
            f"{_fmt_keys(DRIVE_KEYS + FRICTION_KEYS)}"
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
    keys = DRIVE_KEYS + FRICTION_KEYS
    values = {k: _number(path, "drive", k, table[k]) for k in keys if k in table}
    try:
        drive = TwoMassDrive(**values)
    except InputError as exc:
        raise InputError(f"{path}: [drive] {exc}") from None
    theta = values.get("theta")
    note = None if theta is None else degrees_note("theta", theta)
    if note is not None:
        warnings.warn(f"{path}: [drive] {note}", UserWarning, stacklevel=2)
    return drive


def read_actuator_toml(path: PathLike) -> CurrentLoop | None:
    """Read the optional ``[actuator]`` table of a drive file.

    Parameters
    ----------
    path : str or os.PathLike
        The TOML file; ``[actuator]`` holds ``tau_i``, the current loop's time
        constant in s (>= 0; 0 applies the torque exactly).

    Returns
    -------
    CurrentLoop or None
        The current loop, or None when the file has no ``[actuator]`` table.

    Raises
    ------
    InputError
        An unknown or missing key, or a ``tau_i`` that is not a finite number >= 0.
    """
    from .actuator import CurrentLoop

    table = _table(load_toml(path), "actuator", path, required=False)
    if table is None:
        return None
    unknown = [k for k in table if k not in ACTUATOR_KEYS]
    missing = [k for k in ACTUATOR_KEYS if k not in table]
    if unknown or missing:
        raise InputError(
            f"{path}: [actuator] takes exactly the key(s) {_fmt_keys(ACTUATOR_KEYS)} "
            f"(tau_i: current-loop time constant in s); got {_fmt_keys(list(table))}"
            f"{did_you_mean(unknown, ACTUATOR_KEYS)}"
        )
    tau_i = _number(path, "actuator", "tau_i", table["tau_i"])
    try:
        return CurrentLoop(tau_i=tau_i)
    except InputError as exc:
        raise InputError(f"{path}: [actuator] {exc}") from None


def read_uncertainty_toml(path: PathLike) -> dict[str, float]:
    """Read the optional ``[uncertainty]`` table of a drive file.

    Each entry is the relative (fractional) uncertainty of one linear drive parameter
    (``J_M``, ``J_L``, ``k_sh``, ``f_M``, ``f_L``, ``f_sh``; not ``theta``, which is
    estimated), e.g. ``J_L = 0.1`` for +-10 %, of a Coulomb torque (``fc_M``,
    ``fc_L``) whose value the ``[drive]`` table gives, or of a current loop's time
    constant (``tau_i``) whose value the ``[actuator]`` table gives. Linear parameters
    not listed are taken as exact; a Coulomb torque not listed is fitted without a
    prior, a loop not listed is known exactly.

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
        If the file does not parse, the table is empty, holds a key that is not a
        linear drive parameter, a Coulomb torque or ``tau_i``, or a value that is not a
        finite number >= 0.
    """
    doc = load_toml(path)
    _check_top_level(doc, path)
    table = _table(doc, "uncertainty", path, required=False)
    if table is None:
        return {}
    if not table:  # else read as "no table" (all estimated) or "all held": say which
        raise InputError(
            f"{path}: [uncertainty] is empty; list the parameters' relative stds (e.g. "
            "k_sh = 0.1), or remove the table to estimate every linear parameter from the "
            "data"
        )
    # theta has no prior: it is what identification estimates
    allowed = DRIVE_KEYS[:-1] + UNCERTAIN_TERM_KEYS
    if "theta" in table:
        raise InputError(
            f"{path}: [uncertainty] theta: the backlash is what identify estimates, without "
            f"a prior; remove it (list only: {_fmt_keys(allowed)})"
        )
    unknown = [k for k in table if k not in allowed]
    if unknown:
        raise InputError(
            f"{path}: unknown key(s) {_fmt_keys(unknown)} in [uncertainty]"
            f"{did_you_mean(unknown, allowed)}; allowed keys: {_fmt_keys(allowed)}"
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
        raise InputError(f"cannot write {target}: directory {parent} does not exist (create "
                         "it, or write elsewhere)")
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
