"""File-reading options shared by ``identify`` (experiments) and ``simulate --torque``.

Both commands read their files with :mod:`backlashkit.identify.readers`; the options below map
onto its keywords, and :func:`reader_errors` words the reader's advice (the options of its
messages, ``pass sample_time=``) as the flags of the command line (``pass --sample-time TS``).
"""

from __future__ import annotations

import argparse
from contextlib import AbstractContextManager
from typing import Any

from ..errors import InputError, Option
from .main import Flag, flag_names

__all__ = ["READER_FLAGS", "add_file_options", "file_options", "parse_columns",
           "reader_errors"]


def add_file_options(g: Any, *, columns_help: str) -> None:
    """Add ``--columns``, ``--sample-time``, ``--delimiter``, ``--decimal`` and
    ``--resample`` to a parser or argument group.

    Parameters
    ----------
    g : argparse.ArgumentParser or argparse._ArgumentGroup
        Where the options go.
    columns_help : str
        Help of ``--columns`` (which columns the command reads).
    """
    g.add_argument("--columns", metavar="OURS=THEIRS,...", default=None, help=columns_help)
    g.add_argument("--sample-time", type=float, default=None, metavar="TS",
                   help="sample time in s when the file has no time column (t = 0 first)")
    # metavars: the choices, commas among them, would print as {,,;,tab}
    g.add_argument("--delimiter", choices=(",", ";", "tab"), default=None, metavar="SEP",
                   help="CSV separator: ',' (comma), ';' (semicolon) or tab (default: "
                   "detected from the header)")
    g.add_argument("--decimal", choices=(".", ","), default=None, metavar="MARK",
                   help="CSV decimal mark: '.' (point) or ',' (comma) (default: detected)")
    g.add_argument("--resample", choices=("linear",), default=None,
                   help="resample non-uniform time onto a uniform grid (the torque as a "
                   "zero-order hold) and bridge missing samples (default: they are errors)")


def file_options(args: argparse.Namespace) -> dict[str, Any]:
    """The keywords of :func:`backlashkit.identify.readers.read_records` given by the options.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments holding the options of :func:`add_file_options`.

    Returns
    -------
    dict
        ``columns``, ``sample_time``, ``delimiter``, ``decimal``, ``resample``.
    """
    return {"columns": parse_columns(args.columns), "sample_time": args.sample_time,
            "delimiter": "\t" if args.delimiter == "tab" else args.delimiter,
            "decimal": args.decimal, "resample": args.resample}


def parse_columns(text: str | None) -> dict[str, str] | None:
    """``--columns t=time,w_motor=n_mot`` as a mapping (None without the option).

    Parameters
    ----------
    text : str or None
        The option's value.

    Returns
    -------
    dict of str to str, or None
        Our column names to the file's.

    Raises
    ------
    InputError
        If the text is not OURS=THEIRS pairs, or maps a column twice.
    """
    if text is None:
        return None
    out = {}
    for item in text.split(","):
        ours, eq, theirs = item.partition("=")
        if not eq or not ours.strip() or not theirs.strip():
            raise InputError(
                f"--columns must be OURS=THEIRS pairs separated by commas, e.g. "
                f"'t=time,w_motor=n_mot'; got {text!r}"
            )
        key, name = ours.strip(), theirs.strip()
        if key in out:
            raise InputError(f"--columns maps {key!r} twice ({out[key]!r} and {name!r})")
        out[key] = name
    return out


def _columns_flag(option: Option) -> str:
    """``--columns`` with the names the reader asks to map (``t=...,torque=...``)."""
    if option.value is None:
        return "--columns"
    if isinstance(option.value, str):
        return f"--columns {option.value}"
    return "--columns " + ",".join(f"{name}=..." for name in option.value)


def _delimiter_flag(option: Option) -> str:
    if option.value is None:
        return "--delimiter"
    return "--delimiter " + ("tab" if option.value == "\t" else repr(option.value))


#: The reader's options -> the flags of the command line.
READER_FLAGS: dict[str, Flag] = {
    "columns": _columns_flag,
    "sample_time": "--sample-time",
    "delimiter": _delimiter_flag,
    "decimal": "--decimal",
    "resample": "--resample",
}


def reader_errors() -> AbstractContextManager[None]:
    """Word the reader's errors and warnings in the command line's flags.

    Returns
    -------
    contextlib.AbstractContextManager
        :func:`~backlashkit.cli.main.flag_names` of :data:`READER_FLAGS`.
    """
    return flag_names(READER_FLAGS)
