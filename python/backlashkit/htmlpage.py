"""Self-contained HTML report pages: one stylesheet, figures, tables, the page.

Shared by the identification report (:mod:`backlashkit.identify.report`) and the
reproduction reports (``reproduce ravanbod2002``, ``reproduce tao1995``), so that every
report looks alike and opens in any browser without a network (no scripts, no external
files but the figures written beside the page).
"""

from __future__ import annotations

import html
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

__all__ = ["CSS", "bars_table", "figure", "page", "save_figure", "table"]

CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;max-width:1000px;
margin:2em auto;padding:0 1em;color:#222;line-height:1.45}
h1{font-size:1.5em;margin-bottom:.2em}h2{font-size:1.2em;margin-top:1.8em;
border-bottom:1px solid #ddd}
table{border-collapse:collapse;margin:.6em 0}
th,td{border:1px solid #ccc;padding:.25em .6em;text-align:right}
th{background:#f3f3f3}td.l,th.l{text-align:left}
td.met{color:#1a7f37;font-weight:600}td.miss{color:#b3261e;font-weight:600}
figure{margin:1em 0}img{max-width:100%;height:auto;border:1px solid #eee}
figcaption{font-size:.9em;color:#555}.note{color:#555;font-size:.9em}
pre{background:#f7f7f7;padding:.6em;overflow-x:auto;font-size:.85em}
"""


def save_figure(fig: Any, directory: Path, stem: str) -> str:
    """Write ``stem.png`` (shown) and ``stem.svg`` (linked) into ``directory``.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.
    directory : pathlib.Path
        An existing folder.
    stem : str
        File name without suffix.

    Returns
    -------
    str
        ``stem``, for :func:`figure`.
    """
    fig.savefig(directory / f"{stem}.png", dpi=110)
    fig.savefig(directory / f"{stem}.svg")
    return stem


def figure(stem: str, caption: str) -> str:
    """A figure written by :func:`save_figure`: the PNG, linking to the SVG.

    Parameters
    ----------
    stem : str
        File name without suffix, as passed to :func:`save_figure`.
    caption : str
        Caption (plain text; escaped).

    Returns
    -------
    str
        The HTML ``<figure>`` element.
    """
    return (
        f'<figure><a href="{stem}.svg"><img src="{stem}.png" alt="{html.escape(caption)}">'
        f"</a><figcaption>{html.escape(caption)} (<a href=\"{stem}.svg\">SVG</a>)"
        "</figcaption></figure>"
    )


def table(header: Sequence[str], rows: Iterable[Sequence[Any]], *, left: int = 1) -> str:
    """A table of already formatted cells; the first ``left`` columns align left.

    Parameters
    ----------
    header : sequence of str
        Column headings.
    rows : iterable of sequences
        Cells, escaped; a cell given as ``("text", "css-class")`` gets that class.
    left : int, optional
        How many leading columns align left (default 1).

    Returns
    -------
    str
        The HTML ``<table>`` element.
    """

    def cell(tag: str, k: int, value: Any) -> str:
        text, cls = value if isinstance(value, tuple) else (value, None)
        classes = " ".join(c for c in ("l" if k < left else None, cls) if c)
        attr = f' class="{classes}"' if classes else ""
        return f"<{tag}{attr}>{html.escape(str(text))}</{tag}>"

    head = "".join(cell("th", k, h) for k, h in enumerate(header))
    body = "\n".join(
        "<tr>" + "".join(cell("td", k, v) for k, v in enumerate(row)) + "</tr>" for row in rows
    )
    return f"<table><tr>{head}</tr>\n{body}</table>"


def bars_table(checks: Iterable[tuple[str, Any, bool]]) -> str:
    """The table of a reproduction's checks against its paper (its bars).

    Parameters
    ----------
    checks : iterable of (str, object, bool)
        ``(what is checked, measured value, met)`` per check.

    Returns
    -------
    str
        The HTML table, "MET" or "MISSED" in the last column.
    """
    return table(("check", "measured", "result"),
                 ((b, v, ("MET", "met") if m else ("MISSED", "miss")) for b, v, m in checks),
                 left=2)


def page(title: str, sections: Iterable[str]) -> str:
    """A whole HTML document: ``title`` and the sections in order.

    Parameters
    ----------
    title : str
        Page title (plain text; escaped).
    sections : iterable of str
        HTML fragments, in order.

    Returns
    -------
    str
        The self-contained document (inline stylesheet, no scripts).
    """
    return (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        f"<title>{html.escape(title)}</title>\n<style>{CSS}</style>\n</head>\n<body>\n"
        + "\n".join(sections)
        + "\n</body>\n</html>\n"
    )
