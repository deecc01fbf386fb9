"""The page of a release matrix or a bisect (`batch.decide.matrix`): one self-contained ``index.html``, a cell per
comparison (its verdict, the whole image's difference with its interval, the bias ruled out per finest tile, the
p-value map) linking to the comparison's full report."""

from __future__ import annotations

import html
import os
from pathlib import Path

from .._siblings import welch_core as wc
from . import fmt
from .dashboard import STYLE, pvalue_thumbnail
from .statuses import verdict_colour


def _cell(pair, page: Path) -> str:
    colour = verdict_colour(pair.verdict)
    whole = pair.whole_image
    difference = html.escape(fmt.difference(whole)) if whole and whole.get("estimate") is not None else "—"
    bound = "—" if pair.ruled_out is None else f"±{fmt.bound(pair.ruled_out)}"
    thumbnail = pvalue_thumbnail(Path(pair.folder))
    image = f'<img alt="p-value map" src="{thumbnail}">' if thumbnail else ""
    link = html.escape(os.path.relpath(Path(pair.folder) / "report.html", page.parent))
    verdict = html.escape(wc.Verdict(pair.verdict).text)
    return (f'<td class="pair" data-verdict="{pair.verdict}"><a href="{link}">{image}</a>'
            f'<div class="status" style="color:{colour}">{verdict}</div><div>whole image {difference}</div>'
            f'<div class="muted">ruled out per finest tile: {bound}</div></td>')  # fmt: skip


def write_matrix_page(path: Path, title: str, labels: list[str], pairs, note: str = "") -> None:
    """A matrix: a row per reference build, a column per test build, a cell where they were compared."""
    by = {(p.reference, p.test): p for p in pairs}
    head = "".join(f"<th>{html.escape(label)}</th>" for label in labels)
    rows = []
    for a in labels:
        cells = "".join(_cell(by[(a, b)], path) if (a, b) in by else '<td class="muted">—</td>' for b in labels)
        rows.append(f"<tr><th>{html.escape(a)}</th>{cells}</tr>")
    _write(path, title, f'<table id="matrix"><tr><th>reference \\ test</th>{head}</tr>{"".join(rows)}</table>', note)


def write_bisect_page(path: Path, title: str, bisection) -> None:
    """A bisect: its answer, then each step in order with its comparison."""
    rows = "".join(
        f"<tr><td>{number}</td><td><b>{html.escape(step.build)}</b></td><td class='num'>{step.alpha:.2g}</td>"
        + _cell(step.pair, path) + "</tr>"
        for number, step in enumerate(bisection.steps, 1)
    )  # fmt: skip
    head = "<tr><th>step</th><th>build</th><th>alpha</th><th>its comparison</th></tr>"
    table = f'<table id="steps">{head}{rows}</table>'
    _write(path, title, f'<p id="answer"><b>{html.escape(bisection.message)}</b></p>{table}', "")


def _write(path: Path, title: str, body: str, note: str) -> None:
    page = f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<meta name="viewport" content="width=device-width, initial-scale=1"><style>{STYLE}
td.pair{{min-width:160px}}</style></head>
<body><header><h1 id="title">{html.escape(title)}</h1><div class="muted">{html.escape(note)}</div></header>
<main>{body}
<p class="muted">Each cell is one comparison at its alpha (its own question: do the two converge to the same
image?), decided on disjoint passes; click it for its full report. p-value map: log scale, yellow for small p.</p>
</main></body></html>
"""
    wc.formats.atomic_write(path, lambda f: f.write(page.encode("utf-8")))
