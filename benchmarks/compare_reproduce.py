"""Compare two ``backlashkit reproduce ravanbod2002 --json`` documents number by number.

Every value must be identical except the timings (keys containing ``seconds``) and the
worker count (``jobs``), which do not change the estimates. Used to show that a change
leaves the reproduction's estimates as they were, to the last digit::

    backlashkit reproduce ravanbod2002 --runs 10 --seed 2002 --jobs 2 --json-out new.json
    python benchmarks/compare_reproduce.py old.json new.json

Prints ``IDENTICAL (timings excluded)`` and exits 0, or the first 50 differences and
exits 1.
"""

from __future__ import annotations

import json
import sys

#: Keys whose values may differ between identical reproductions.
SKIP = ("seconds", "jobs")


def differences(a, b, path: str = "") -> list[str]:
    """Paths at which the JSON values ``a`` and ``b`` differ (timings skipped)."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for k in sorted(set(a) | set(b)):
            if any(s in k for s in SKIP):
                continue
            if k not in a or k not in b:
                out.append(f"{path}/{k}: only in {'new' if k not in a else 'old'}")
            else:
                out += differences(a[k], b[k], f"{path}/{k}")
        return out
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{path}: lengths {len(a)} and {len(b)}"]
        return [d for i, (x, y) in enumerate(zip(a, b, strict=True))
                for d in differences(x, y, f"{path}[{i}]")]
    return [] if a == b else [f"{path}: {a!r} and {b!r}"]


def main() -> int:
    if len(sys.argv) != 3:
        print("usage: compare_reproduce.py OLD.json NEW.json", file=sys.stderr)
        return 2
    old, new = (json.load(open(p, encoding="utf-8")) for p in sys.argv[1:])
    found = differences(old, new)
    print("\n".join(found[:50]) if found else "IDENTICAL (timings excluded)")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
