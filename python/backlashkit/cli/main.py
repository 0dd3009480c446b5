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
import difflib
import importlib
import os
import re
import sys
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path

from ..errors import Diagnostic, InputError, Option

__all__ = ["flag_names", "main", "spell", "word"]

#: Modules that register subcommands, in the order they are listed by ``--help``.
SUBCOMMAND_MODULES = ("simulate", "identify", "control", "reproduce", "delay_margin", "fleet")


class _Parser(argparse.ArgumentParser):
    """One line per error, naming the subcommand's help, and the option meant where a
    given one is misspelled."""

    #: The subcommands' parsers by name (the top level's, set by :func:`build_parser`).
    commands: Mapping[str, argparse.ArgumentParser] = {}

    def parse_known_args(self, args=None, namespace=None):
        self._given = list(sys.argv[1:] if args is None else args)
        parsed, extra = super().parse_known_args(args, namespace)
        command = self.commands.get(getattr(parsed, "command", None) or "")
        if extra and command is not None:
            # argparse reports what a subcommand does not know from the top level,
            # whose help does not list that subcommand's options
            command.error(f"unrecognized arguments: {' '.join(extra)}")
        return parsed, extra

    def error(self, message: str):  # one line, status 2, as argparse does, without usage spam
        self.exit(2, f"backlashkit: error: {message}{_meant_choice(message)}{self._meant()}"
                     f"{self._dash_value(message)} (see '{self.prog} --help')\n")

    def _dash_value(self, message: str) -> str:
        """``; a value that starts with '-' goes after '=': --h-range=-1,5`` where
        argparse took such a value for an option and found the flag before it bare."""
        found = _EXPECTED_ONE.search(message)
        given = getattr(self, "_given", [])
        if found is None:
            return ""
        flags = found.group(1).split("/")
        for flag, value in zip(given, given[1:], strict=False):
            if flag in flags and value.startswith("-"):
                return f"; a value that starts with '-' goes after '=': {flag}={value}"
        return ""

    def _meant(self) -> str:
        """``; --drvie: did you mean --drive?`` for each given option this parser does
        not have and that is close to one it has."""
        known = list(self._option_string_actions)
        hints = []
        for token in getattr(self, "_given", []):
            flag = token.split("=", 1)[0]
            if not flag.startswith("--") or flag in known or any(
                    k.startswith(flag) for k in known):  # argparse takes a unique prefix
                continue
            close = difflib.get_close_matches(flag, known, n=1)
            if close:
                hints.append(f"{flag}: did you mean {close[0]}?")
        return "".join(f"; {h}" for h in hints)


#: argparse's words for an option given without its value.
_EXPECTED_ONE = re.compile(r"argument (\S+): expected one argument")
#: argparse's words for a value outside an argument's choices (a subcommand's too).
_INVALID_CHOICE = re.compile(r"invalid choice: '([^']*)' \(choose from (.*)\)")


def _meant_choice(message: str) -> str:
    """``; did you mean 'identify'?`` where ``message`` is argparse's refusal of a
    value close to one of its choices."""
    found = _INVALID_CHOICE.search(message)
    if found is None:
        return ""
    choices = re.findall(r"'([^']*)'", found.group(2))
    close = difflib.get_close_matches(found.group(1), choices, n=1)
    return f"; did you mean '{close[0]}'?" if close else ""


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
    parser.commands = sub.choices
    return parser


#: A flag spelled from a library parameter: the flag (``--resample``; an advised value
#: follows it, ``--resample linear``), or a function of the option that words it.
Flag = str | Callable[[Option], str]

#: The innermost flags of :func:`flag_names`, used to word the library's warnings too.
_ACTIVE_FLAGS: list[Mapping[str, Flag]] = []


def spell(option: Option, flags: Mapping[str, Flag]) -> str | None:
    """The command line's words for a library option (None: not one of ``flags``).

    Parameters
    ----------
    option : Option
        The option a library message names or advises.
    flags : mapping of str to Flag
        Library parameter -> flag.

    Returns
    -------
    str or None
    """
    flag = flags.get(option.name)
    if flag is None or not isinstance(flag, str):
        return None if flag is None else flag(option)
    if option.value is None or option.value is True:
        return flag
    return f"{flag} {option.value}"


def word(exc: Diagnostic, flags: Mapping[str, Flag]) -> str:
    """A library diagnostic in the command line's words.

    Every :class:`~backlashkit.errors.Option` of the message is spelled as its flag;
    a validation message without options names its parameter first
    (``final_horizon must be > 0``), and that name becomes the flag.

    Parameters
    ----------
    exc : Diagnostic
        An error or warning of the library.
    flags : mapping of str to Flag
        Library parameter -> flag, e.g. ``{"final_horizon": "--final-horizon"}``.

    Returns
    -------
    str
        The message, one line.
    """
    text = exc.worded(lambda option: spell(option, flags))
    if not exc.options():
        for name, flag in flags.items():
            if isinstance(flag, str) and text.startswith(name + " "):
                return flag + text[len(name):]
    return text


@contextmanager
def flag_names(flags: Mapping[str, Flag]) -> Iterator[None]:
    """Name the command-line flags, not the library parameters, in errors and warnings.

    Inside this context an :class:`InputError` is raised again in the command line's
    words (:func:`word`), and the library's warnings printed by :func:`main` are
    worded alike.

    Parameters
    ----------
    flags : mapping of str to Flag
        Library parameter name -> flag, e.g. ``{"final_horizon": "--final-horizon"}``.

    Yields
    ------
    None
    """
    _ACTIVE_FLAGS.append(flags)
    try:
        yield
    except InputError as exc:
        said = word(exc, flags)
        if said == str(exc):
            raise
        raise InputError(said) from exc
    finally:
        _ACTIVE_FLAGS.pop()


def missing_directory(flag: str, out: Path) -> str:
    """The message for an output file whose directory is missing (or is a file)."""
    for parent in (out.parent, *out.parent.parents):
        if parent.exists() and not parent.is_dir():
            return f"{flag} {out}: {parent} is a file, not a directory"
    return f"{flag} {out}: directory {out.parent} does not exist (create it, or write elsewhere)"


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A library warning as the command line's notes are: one line on stderr."""
    if isinstance(message, Diagnostic) and _ACTIVE_FLAGS:
        message = word(message, _ACTIVE_FLAGS[-1])
    print(f"backlashkit: note: {' '.join(str(message).split())}", file=sys.stderr)


def given_as(args: argparse.Namespace, argv: Sequence[str], path) -> str | None:
    """Which argument of the command line gave ``path``: ``"given to --drive"`` for
    an option, ``"one of the records"`` for a positional argument's (the parser's
    name of it), or None where no argument holds it (a file named inside another)."""
    given = {token.split("=", 1)[0] for token in argv if token.startswith("--")}
    for dest, value in vars(args).items():
        values = value if isinstance(value, (list, tuple)) else [value]
        if not any(isinstance(v, (str, os.PathLike)) and os.fspath(v) == os.fspath(path)
                   for v in values):
            continue
        flag = "--" + dest.replace("_", "-")
        if flag in given:
            return f"given to {flag}"
        return f"one of the {dest}" if isinstance(value, (list, tuple)) else f"the {dest}"
    return None


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
        if not exc.filename:
            return fail(str(exc))
        given = given_as(args, sys.argv[1:] if argv is None else argv, exc.filename)
        return fail(f"file not found: {exc.filename}{f' ({given})' if given else ''}: "
                    "check the path")
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
