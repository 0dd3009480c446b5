"""Command-line interface: ``backlashkit <command> ...``.

Each subcommand lives in its own module (``cli/<name>.py``) exposing
``add_parser(subparsers)``, which registers the subcommand and sets ``func`` to a
callable ``func(args) -> int``. Conventions shared by every subcommand:

* results go to stdout (``--json``: one JSON document, nothing else), progress and
  messages to stderr;
* bad input exits with status 2 and a single line ``backlashkit: error: <reason>`` on
  stderr, never a traceback;
* nothing the user gave is overwritten unless ``--force`` is passed.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import warnings
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path

from ..errors import InputError

__all__ = ["flag_names", "main"]

#: Modules that register subcommands, in the order they are listed by ``--help``.
SUBCOMMAND_MODULES = ("simulate", "identify", "control", "reproduce")


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, status 2, as argparse does, without usage spam
        self.exit(2, f"backlashkit: error: {message} (see '{self.prog} --help')\n")


def build_parser() -> argparse.ArgumentParser:
    """The top-level parser with every available subcommand registered."""
    from .. import __version__

    parser = _Parser(
        prog="backlashkit",
        description="Simulate drive trains with backlash, identify the backlash, cancel it.",
    )
    parser.add_argument("--version", action="version", version=f"backlashkit {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for name in SUBCOMMAND_MODULES:
        try:
            module = importlib.import_module(f".{name}", __package__)
        except ModuleNotFoundError as exc:  # a subcommand not built yet
            if exc.name != f"{__package__}.{name}":
                raise
            continue
        module.add_parser(sub)
    return parser


@contextmanager
def flag_names(flags: Mapping[str, str]) -> Iterator[None]:
    """Name the command-line flag, not the library parameter, in input errors.

    The library validates its parameters and names them (``final_horizon must be >
    0``); a CLI user typed ``--final-horizon``. Inside this context an
    :class:`InputError` whose message starts with a parameter of ``flags`` is raised
    again with the flag in its place.

    Parameters
    ----------
    flags : mapping of str to str
        Library parameter name -> flag, e.g. ``{"final_horizon": "--final-horizon"}``.

    Yields
    ------
    None
    """
    try:
        yield
    except InputError as exc:
        message = str(exc)
        for name, flag in flags.items():
            if message.startswith(name + " "):
                raise InputError(flag + message[len(name):]) from exc
        raise


def missing_directory(flag: str, out: Path) -> str:
    """The message for an output file whose directory is missing (or is a file)."""
    for parent in (out.parent, *out.parent.parents):
        if parent.exists() and not parent.is_dir():
            return f"{flag} {out}: {parent} is a file, not a directory"
    return f"{flag} {out}: directory {out.parent} does not exist"


def check_reproduce_outputs(json_path: str | None, report: str | None,
                            force: bool) -> Path | None:
    """Refuse, before any run, the ``--json FILE`` and ``--report DIR`` of a ``reproduce``
    target that exist (without ``--force``), sit in a missing directory or cannot be
    written; return the report directory.

    Parameters
    ----------
    json_path : str or None
        ``--json`` (``"-"``: standard output).
    report : str or None
        ``--report``.
    force : bool
        ``--force``.

    Returns
    -------
    pathlib.Path or None
        The report directory.
    """
    from ..io import check_writable

    if json_path not in (None, "-"):
        if Path(json_path).exists() and not force:
            raise InputError(f"--json {json_path} already exists; pass --force to overwrite it")
        if not Path(json_path).parent.is_dir():
            raise InputError(missing_directory("--json", Path(json_path)))
        check_writable(json_path, "--json")
    if report is None:
        return None
    rep = Path(report)
    if rep.exists() and not rep.is_dir():
        raise InputError(f"--report {rep} exists and is not a directory")
    if rep.exists() and any(rep.iterdir()) and not force:
        raise InputError(f"--report {rep} is not empty; pass --force to overwrite its files")
    check_writable(rep, "--report", directory=True)
    return rep


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A library warning as the command line's notes are: one line on stderr."""
    print(f"backlashkit: note: {' '.join(str(message).split())}", file=sys.stderr)


def fail(message: str) -> int:
    """Print a one-line error on stderr and return exit status 2."""
    print(f"backlashkit: error: {message}", file=sys.stderr)
    return 2


def _silence_stdout() -> None:
    """Point stdout at /dev/null, so that the interpreter's last flush does not fail on
    the closed pipe too (the recipe of Python's ``signal`` documentation)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):  # stdout is no file (captured in tests)
        pass


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; return the exit status."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version, or a usage error already printed
        return int(exc.code or 0) if not isinstance(exc.code, str) else 2
    try:
        with warnings.catch_warnings():  # one line on stderr, not Python's two
            warnings.showwarning = _one_line_warning
            return int(args.func(args) or 0)
    except InputError as exc:
        return fail(str(exc))
    except BrokenPipeError:  # the reader closed stdout (| head): stop quietly
        _silence_stdout()
        return 1
    except FileNotFoundError as exc:
        return fail(f"file not found: {exc.filename}" if exc.filename else str(exc))
    except IsADirectoryError as exc:
        return fail(f"expected a file, got a directory: {exc.filename}")
    except NotADirectoryError as exc:
        return fail(f"not a directory: a component of {exc.filename} is a file")
    except PermissionError as exc:
        return fail(f"permission denied: {exc.filename}")
    except OSError as exc:
        return fail(f"{exc.strerror or exc}: {exc.filename}" if exc.filename else str(exc))
    except (ValueError, ArithmeticError) as exc:
        # the compiled core and NumPy refuse what they cannot compute (a mode too fast
        # for the sample time, a diverging simulation, an overflow): this input is out
        # of the model's reach; say so on one line rather than with a traceback
        text = " ".join(str(exc).split()) or type(exc).__name__
        return fail(f"cannot compute with this input: {text}")
    except KeyboardInterrupt:
        return fail("interrupted")


if __name__ == "__main__":
    sys.exit(main())
