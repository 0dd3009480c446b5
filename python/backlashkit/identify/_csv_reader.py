"""CSV text files to raw channels, for :mod:`backlashkit.identify.readers` (any of
``,``, ``;`` or tab as separator, decimal point or decimal comma)."""

from __future__ import annotations

import csv
import io
import math
import os
import re
import warnings
from collections.abc import Callable

import numpy as np

from ..errors import InputError, Option

PathLike = str | os.PathLike[str]

#: Our names of a record's channels, in order.
FIELDS = ("t", "torque", "w_motor", "w_load")
#: The same for a record of encoder angles (``read_records(angles=True)``).
ANGLE_FIELDS = ("t", "torque", "phi_motor", "phi_load")

DELIMITERS = (",", ";", "\t")

#: The readers' options that their messages name or advise (a front end words them as
#: its own options: :class:`~backlashkit.errors.Option`).
COLUMNS = Option("columns", None)
RESAMPLE = Option("resample", "linear")
SAMPLE_TIME = Option("sample_time", None)
#: The advice to give a sample time instead of a time column.
PASS_SAMPLE_TIME = Option("sample_time", "TS", python="sample_time=")
DELIMITER = Option("delimiter", None)


def map_columns(names) -> Option:
    """The advice to map the file's names of ``names`` (our names) with ``columns``."""
    return Option("columns", tuple(names),
                  python="columns={" + ", ".join(f"{f!r}: ..." for f in names) + "}")



# (name of the record, raw channels (t may be absent), label of sample i, time precision)
_Raw = tuple[str, dict[str, np.ndarray], Callable[[int], str], float]

#: The speeds' and the encoders' angles' columns, by our names.
_SPEEDS, _ANGLES = ("w_motor", "w_load"), ("phi_motor", "phi_load")
#: Leading bytes of files that are no text, with what they likely are.
_BINARY_HEADS = ((b"PK\x03\x04", "a zip archive (an Excel .xlsx workbook?)"),
                 (b"\xd0\xcf\x11\xe0", "an Excel .xls workbook"))


def _refuse_other_measure(name: str, header: list[str], header_no: int, need: list[str],
                          missing: list[str]) -> None:
    """Refuse a file that lacks the speeds but holds the encoders' angles (or the
    reverse), with the option that reads what it holds; ``need`` and ``missing`` (the
    channels without a column) by our names."""
    if set(_SPEEDS) <= set(need) and set(_SPEEDS) & set(missing) and set(_ANGLES) <= set(header):
        raise InputError(
            f"{name}: no column 'w_motor', 'w_load' but the encoders' angles 'phi_motor', "
            f"'phi_load' (line {header_no}): read them with ", Option("angles", True),
            " (in rad) or ", Option("counts_per_rev", None), " N (in counts)")
    if set(_ANGLES) <= set(need) and set(_ANGLES) & set(missing) and set(_SPEEDS) <= set(header):
        raise InputError(
            f"{name}: no column 'phi_motor', 'phi_load' but the speeds 'w_motor', "
            f"'w_load' (line {header_no}): leave out ", Option("angles", None), " and ",
            Option("counts_per_rev", None), " to read the speeds")


def _from_csv(name: str, mapping: dict[str, str], need: list[str], delimiter, decimal) -> _Raw:
    with open(name, "rb") as fh:
        head = fh.read(4)
    for magic, what in _BINARY_HEADS:
        if head.startswith(magic):
            raise InputError(f"{name}: is {what}, not CSV text; export the sheet as CSV "
                             "(or save the data as .mat or .npz)")
    head = head[:2]
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
            f"{sep[delimiter]}; pass ", Option("delimiter", others[0])
        )
    _refuse_other_measure(name, header, header_no, need,
                          [f for f in need if mapping[f] not in header])
    if missing:
        sep = {"\t": "tab", ",": "','", ";": "';'"}[delimiter]
        raise InputError(
            f"{name}: no column {', '.join(map(repr, missing))} in the header (line "
            f"{header_no}, separator {sep}: {header!r}); map the file's names with ",
            map_columns([f for f in mapping if f in need or f == "t"]),
            *((" or pass ", PASS_SAMPLE_TIME, " if there is no time column") if "t" in need
              else ())
        )
    if "t" not in need and mapping["t"] in header:
        need = ["t", *need]  # read it so that the conflict with sample_time is reported
    width = len(header)
    for r, row in enumerate(data):
        if len(row) != width:
            raise InputError(
                f"{name}: line {numbers[r]} has {len(row)} field(s) but the header has {width}; "
                "check the separator (", Option("delimiter", delimiter), ") and the decimal "
                "mark"
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
        bad: tuple = ()
        if "_" in cell:
            bad = ("has an underscore, which is no number format of a measurement file",)
        elif decimal == "," and "." in cell:
            bad = ("has a '.' but the decimal mark is ','; thousands separators are not "
                   "read: remove them (or pass ", Option("decimal", "."),
                   " if '.' is the decimal mark)")
        if bad:
            raise InputError(f"{name}: line {numbers[r]}, column {column!r}: {raw!r} ", *bad)
        if decimal == ",":
            cell = cell.replace(",", ".")
        try:
            out[r] = float(cell)
        except ValueError:
            hint: tuple = (
                ("; for decimal commas pass ", Option("decimal", ","), " with ", DELIMITER,
                 " ';' or a tab")
                if "," in raw and decimal == "."
                else ()
            )
            if _DATE_TIME.search(cell):
                hint = ("; a date or clock time is no time in s: convert the column to "
                        "seconds, or remove it and pass ", PASS_SAMPLE_TIME)
            raise InputError(
                f"{name}: line {numbers[r]}, column {column!r}: {raw!r} is not a number",
                *(hint or ("; fix or remove that line",))
            ) from None
        if math.isinf(out[r]):
            raise InputError(
                f"{name}: line {numbers[r]}, column {column!r}: {raw!r} is infinite; fix the file"
            )
    return out

def _precision(arr: np.ndarray) -> float:
    if arr.dtype == np.float32:
        return 4.0 * float(np.finfo(np.float32).eps) * float(np.max(np.abs(arr), initial=0.0))
    return 0.0
