"""The README and docs/ run as written, and print what they say they print.

Conventions of the Markdown code blocks (README.md and docs/**/*.md):

* A `````python`` block is run in order with the blocks before it in the same file, in
  one namespace, once as a script and once pasted line by line into
  :class:`code.InteractiveConsole` (as into ``python``'s interactive shell: a compound
  statement needs a blank line after it, a blank line inside a function ends it). Both
  runs must print the same lines, and those lines must be the ``# -> expected``
  comments of the blocks, in order. Numbers are compared to the last printed digit
  (one unit of it either way: a last digit that rounds differently on another
  machine is no error).
* A `````sh`` block is run command by command (a trailing ``\\`` continues a
  command) with ``bash`` in a scratch directory holding a copy of ``examples/`` and a
  link to ``benchmarks/``, the virtual environment's ``bin/`` first on ``PATH`` (so
  ``backlashkit`` and ``python`` are the project's), as a user in the repository root
  would run them. Every command must exit 0, and a ``# -> text`` comment line after a
  command is text its output (stdout and stderr) must contain.
* A ``# slow: why`` comment line before a command marks a long run (a study, a
  benchmark): it runs only with ``BACKLASHKIT_DOCS_SLOW=1``. Otherwise, and for a
  command after ``# not run: why`` (one that needs the reader's own files), the test
  checks that every ``--option`` it uses is one its program's ``--help`` lists.
* ``make ...`` lines are the quick start (``make test`` runs this very test, ``make
  demo`` takes minutes): the test checks that the Makefile has those targets.
"""

from __future__ import annotations

import code
import contextlib
import io
import math
import os
import re
import shlex
import shutil
import subprocess
import sys
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = sorted((ROOT / "docs").rglob("*.md")) if (ROOT / "docs").is_dir() else []
BIN = Path(sys.executable).parent
SLOW = os.environ.get("BACKLASHKIT_DOCS_SLOW") == "1"
#: Longest a single documented command may take (the slow ones included).
COMMAND_TIMEOUT = 1800
#: The README is a user's first page: at most about this many lines (issue 18).
README_MAX_LINES = 250

EXPECT = "# -> "
BLOCK = re.compile(r"^[ \t]*```(\w+)\n(.*?)^[ \t]*```", re.S | re.M)  # also in lists


def blocks(path: Path, lang: str) -> list[str]:
    return [body for kind, body in BLOCK.findall(path.read_text(encoding="utf-8"))
            if kind == lang]


# --- Python blocks --------------------------------------------------------------------


def expected_output(source: str) -> list[str]:
    return [line.strip()[len(EXPECT):] for line in source.splitlines()
            if line.strip().startswith(EXPECT)]


NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def _unit(text: str) -> float:
    """One unit of the last digit printed in ``text`` (a number)."""
    mantissa, _, exponent = text.lower().partition("e")
    decimals = len(mantissa.partition(".")[2])
    return 10.0 ** (int(exponent or 0) - decimals)


def same_line(got: str, want: str) -> bool:
    """Equal, numbers to one unit of the expected last digit."""
    if "".join(NUMBER.sub("#", got).split()) != "".join(NUMBER.sub("#", want).split()):
        return False  # the text around the numbers, whitespace aside (numpy pads)
    for g, w in zip(NUMBER.findall(got), NUMBER.findall(want), strict=True):
        if not math.isclose(float(g), float(w), rel_tol=0, abs_tol=1.01 * _unit(w)):
            return False
    return True


def check_output(printed: str, want: list[str], where: str) -> None:
    got = [line.strip() for line in printed.splitlines() if line.strip()]
    assert len(got) == len(want), f"{where} printed {got}, the comments say {want}"
    for g, w in zip(got, want, strict=True):
        assert same_line(g, w), f"{where} printed {g!r} where its comment says {w!r}"


class _Console(code.InteractiveConsole):
    """The interactive shell, recording what it would show as an error."""

    def __init__(self) -> None:
        super().__init__(locals={"__name__": "__console__"})
        self.errors: list[str] = []

    def showsyntaxerror(self, filename=None, **kwargs) -> None:
        self.errors.append(f"SyntaxError: {sys.exc_info()[1]}")

    def showtraceback(self) -> None:
        self.errors.append(f"{sys.exc_info()[0].__name__}: {sys.exc_info()[1]}")


def run_script(source: str, name: str) -> str:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        exec(compile(source, name, "exec"), {"__name__": "__main__"})  # noqa: S102
    return out.getvalue()


def run_console(source: str) -> tuple[str, list[str]]:
    console, out = _Console(), io.StringIO()
    with contextlib.redirect_stdout(out), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for line in source.splitlines():
            console.push(line)
        console.push("")  # the user presses Enter once more after pasting
    return out.getvalue(), console.errors


def python_source(path: Path) -> str:
    return "\n".join(blocks(path, "python"))


# --- shell blocks ---------------------------------------------------------------------


@dataclass
class Command:
    text: str
    line: int
    expect: list[str] = field(default_factory=list)
    slow: str | None = None
    not_run: str | None = None


def commands(path: Path) -> list[Command]:
    """The commands of the file's ``sh`` blocks, in order, with their markers."""
    out: list[Command] = []
    text = path.read_text(encoding="utf-8")
    for match in BLOCK.finditer(text):
        if match.group(1) != "sh":
            continue
        first = text.count("\n", 0, match.start(2)) + 1
        slow = not_run = None
        pending = ""
        for k, raw in enumerate(match.group(2).splitlines()):
            line = raw.strip()
            if pending:
                pending += " " + line.rstrip("\\").strip()
                if not line.endswith("\\"):
                    out[-1].text = pending
                    pending = ""
                continue
            if line.startswith(EXPECT):
                assert out, f"{path.name}:{first + k}: '# ->' before any command"
                out[-1].expect.append(line[len(EXPECT):])
            elif line.startswith("# slow:"):
                slow = line[len("# slow:"):].strip()
            elif line.startswith("# not run:"):
                not_run = line[len("# not run:"):].strip()
            elif line and not line.startswith("#"):
                body = line.split("  #")[0].rstrip() if not line.endswith("\\") else line
                out.append(Command(body.rstrip("\\").strip(), first + k, slow=slow,
                                   not_run=not_run))
                slow = not_run = None
                if line.endswith("\\"):
                    pending = out[-1].text
    return out


def scratch(tmp_path: Path) -> Path:
    shutil.copytree(ROOT / "examples", tmp_path / "examples")
    (tmp_path / "benchmarks").symlink_to(ROOT / "benchmarks")
    return tmp_path


def environment() -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = f"{BIN}{os.pathsep}{env.get('PATH', '')}"
    env["VIRTUAL_ENV"] = str(BIN.parent)
    env["MPLBACKEND"] = "Agg"
    return env


def check_options(cmd: Command, cwd: Path) -> None:
    """Every ``--option`` of ``cmd`` is one its program's ``--help`` lists."""
    words = shlex.split(cmd.text.split(" > ")[0])
    program = [w for w in words if not w.startswith("-")]
    n = next((i for i, w in enumerate(words) if w.startswith("-")), len(words))
    # the program and its subcommands: the words before the first option, up to a file
    head = [w for w in words[:n] if not re.search(r"[./]", w) or w == program[0]
            or w.endswith(".py")]
    options = {w.split("=")[0] for w in words if w.startswith("--")}
    script = next((w for w in head if w.endswith(".py")), None)
    if script is not None:
        assert (cwd / script).is_file(), f"line {cmd.line}: no {script}"
        if not options:  # a script without options may not parse --help: it would run
            return
    result = subprocess.run(["bash", "-c", shlex.join([*head, "--help"])], cwd=cwd,
                            env=environment(), capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, f"{shlex.join(head)} --help failed: {result.stderr}"
    for option in options:
        assert option in result.stdout, (
            f"line {cmd.line}: {option} is not an option of {shlex.join(head)}")


def run_commands(path: Path, tmp_path: Path) -> None:
    cwd = scratch(tmp_path)
    makes = []
    for cmd in commands(path):
        where = f"{path.relative_to(ROOT)}:{cmd.line}: {cmd.text}"
        if cmd.text.startswith("make "):
            makes.append(cmd.text.split()[1])
            continue
        if cmd.not_run is not None or (cmd.slow is not None and not SLOW):
            check_options(cmd, cwd)
            continue
        result = subprocess.run(["bash", "-c", cmd.text], cwd=cwd, env=environment(),
                                capture_output=True, text=True, timeout=COMMAND_TIMEOUT)
        output = result.stdout + result.stderr
        assert result.returncode == 0, f"{where}\nexit {result.returncode}:\n{output}"
        for text in cmd.expect:
            assert text in output, f"{where}\nprinted no {text!r}:\n{output}"
    targets = re.findall(r"^([\w-]+):", (ROOT / "Makefile").read_text(), re.M)
    for target in makes:
        assert target in targets, f"{path.name}: the Makefile has no target {target!r}"


# --- the tests ------------------------------------------------------------------------


def test_readme_is_short():
    lines = README.read_text(encoding="utf-8").count("\n")
    assert lines <= README_MAX_LINES, f"README.md has {lines} lines"


def test_readme_has_examples():
    assert len(blocks(README, "python")) >= 2
    assert len(commands(README)) >= 6


@pytest.mark.parametrize("mode", ["script", "console"])
def test_readme_python_blocks_print_what_they_say(mode, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    source = python_source(README)
    want = expected_output(source)
    assert want, "the README's Python blocks check no printed value"
    if mode == "script":
        printed = run_script(source, "README.md")
    else:
        printed, errors = run_console(source)
        assert not errors, f"pasted into the interactive shell: {errors}"
    check_output(printed, want, f"README.md ({mode})")


def test_readme_shell_commands_run(tmp_path):
    run_commands(README, tmp_path)


@pytest.mark.parametrize("doc", DOCS, ids=[str(d.relative_to(ROOT)) for d in DOCS])
def test_docs_run_as_written(doc, tmp_path, monkeypatch):
    run_commands(doc, tmp_path / "sh")
    source = python_source(doc)
    if source:
        monkeypatch.chdir(tmp_path)
        want = expected_output(source)
        check_output(run_script(source, doc.name), want, f"{doc.name} (script)")
        printed, errors = run_console(source)
        assert not errors, f"{doc.name} pasted into the interactive shell: {errors}"
        check_output(printed, want, f"{doc.name} (console)")


def test_docs_link_to_existing_files():
    for page in [README, *DOCS]:
        text = page.read_text(encoding="utf-8")
        for target in re.findall(r"\]\(([^)#:]+)(?:#[^)]*)?\)", text):
            assert (page.parent / target).exists(), f"{page.name} links to missing {target}"


def test_console_catches_a_missing_blank_line():
    """The console check is no formality: the README's first failure, a ``def``
    followed at once by code (issue 21), is a syntax error there."""
    _, errors = run_console("def f(x):\n    return x\ny = f(1)\n")
    assert errors and errors[0].startswith("SyntaxError")
    _, errors = run_console("def f(x):\n    return x\n\ny = f(1)\n")
    assert not errors


def test_expected_values_are_compared_to_the_last_digit():
    assert same_line("0.03482 8.5e-05 [0.03466 0.03499]", "0.03482 8.5e-05 [0.03466 0.03499]")
    assert same_line("0.03483", "0.03482")
    assert not same_line("0.03484", "0.03482")
    assert not same_line("0.0348 x", "0.0348 y")
