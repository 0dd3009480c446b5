"""The ``backlashkit`` command line: it parses, calls the library and words the
library's results and refusals; the rules live in the library."""

from __future__ import annotations

from .main import main

__all__ = ["main"]
