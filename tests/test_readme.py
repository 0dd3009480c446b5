"""The README's Python examples run as written (the README must stay true)."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"


def python_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), re.S)


def test_readme_has_python_examples():
    assert len(python_blocks()) >= 2


@pytest.mark.parametrize("index", range(len(python_blocks())))
def test_readme_python_block_runs(index):
    namespace: dict = {}
    source = "\n".join(python_blocks()[: index + 1])  # later blocks build on earlier ones
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        exec(compile(source, f"README.md block {index}", "exec"), namespace)  # noqa: S102
