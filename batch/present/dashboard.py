"""The dashboard of a suite run: one self-contained ``index.html`` with a row per case and device, failing ones
first (thumbnails of the reference and the test side, hovering one shows the other, their per-pixel difference
and the p-value map; the verdict, the largest effect with its interval, passes and seconds spent) linking to each
case's full report."""

from __future__ import annotations

import html
import os
from pathlib import Path

import numpy as np

from .._siblings import welch_core as wc
from ..errors import Exit
from ..jobs.protocol import CaseStatus
from . import fmt
from .statuses import FIRST, STATUS_COLOURS, STATUSES

THUMBNAIL = 96  # pixels, the longer side

#: The pages' one style sheet (the dashboard, the matrix's and the audit's pages).
STYLE = """
body{font:14px/1.45 system-ui,sans-serif;margin:0;color:#1d1d1f;background:#f6f6f4}
header{padding:16px 24px;background:#fff;border-bottom:1px solid #ddd}
h1{margin:0;font-size:24px}
main{padding:16px 24px}
table{border-collapse:collapse;background:#fff;border:1px solid #ddd}
td,th{padding:6px 10px;text-align:left;vertical-align:middle;border-bottom:1px solid #eee}
th{font-weight:600;background:#fafafa}
img{width:96px;height:96px;object-fit:contain;image-rendering:pixelated;background:#777;display:block}
.ab .other,.ab:hover .shown{display:none}
.ab:hover .other{display:block}
.status{font-weight:600;text-transform:uppercase;font-size:12px;letter-spacing:.04em}
.num{text-align:right;font-variant-numeric:tabular-nums}
.muted{color:#777;font-size:12px;max-width:340px}
.counts span{margin-right:14px}
"""


def write_dashboard(path: Path, summary: dict, outcomes, references: list[Path]) -> None:
    """Write the dashboard of `outcomes` (``batch.decide.suite.CaseResult``) with `summary` (``summary.json``'s
    content) and each case's reference statistics file."""
    # What needs a look first (`FIRST`; a stable sort: the suite's order within each status).
    rows = sorted(zip(outcomes, summary["cases"], references, strict=True), key=lambda row: FIRST.index(row[0].status))
    rows = "".join(_row(o, record, ref) for o, record, ref in rows)
    counts = "".join(
        f'<span style="color:{STATUS_COLOURS[k]}" title="{STATUSES[k].meaning}">{v} {k}</span>'
        for k, v in summary["counts"].items()
        if v
    )
    nothing_ran = all(o.status == CaseStatus.SKIPPED for o in outcomes)
    verdict = {Exit.OK: "every case passed", Exit.BIASED: "a case failed", Exit.USAGE: "nothing ran: every case was "
               "skipped" if nothing_ran else "a case could not run", Exit.INCONCLUSIVE: "a case is inconclusive or "
               "underpowered"}  # fmt: skip
    page = f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>Suite {html.escape(summary["suite"])}: \
{verdict[summary["exit_code"]]}</title>
<meta name="viewport" content="width=device-width, initial-scale=1"><style>{STYLE}</style></head>
<body><header><h1 id="title">Suite {html.escape(summary["suite"])}: {verdict[summary["exit_code"]]}</h1>
<div class="counts" id="counts">{counts}</div>
<div class="muted">alpha {summary["alpha"]:g} per case · references {html.escape(_near(summary["refs"], path))} ·
{html.escape(_near(summary["file"], path))}</div></header>
<main><table id="cases"><thead><tr><th>case</th><th>device</th><th>status</th><th>reference</th><th>test</th>
<th>test − reference</th><th>p-value map</th><th>verdict</th><th>difference</th><th class="num">passes</th>
<th class="num">seconds</th><th>report</th></tr></thead><tbody>{rows}</tbody></table>
<p class="muted">Failing cases first. Hover a render to see the other side (A/B). Thumbnails share the reference's
exposure; the difference is per pixel, blue where the test side is darker and red where brighter, its ends the
±value shown below it (of the reference's mean brightness). p-value map: log scale, yellow for small p (1e-12
and below), violet for p near 1, grey where no tile-channel could be tested.</p></main></body></html>
"""
    wc.formats.atomic_write(path, lambda f: f.write(page.encode("utf-8")))


def _near(target: str, page: Path) -> str:
    """`target` relative to the page's folder (the dashboard may be moved with its run folder)."""
    try:
        return os.path.relpath(target, page.parent)
    except ValueError:  # another drive
        return target


def _row(outcome, record: dict, reference: Path) -> str:
    colour = STATUS_COLOURS[outcome.status]
    ref, test, difference_url, scale, pmap = _thumbnails(outcome, reference)
    cells = "".join(_ab(shown, other, name) for shown, other, name in ((ref, test, "reference"), (test, ref, "test")))
    if difference_url:
        scale_text = (
            f'<div class="muted">±{100 * scale:.2g} %</div>'
            if scale < 0.1
            else f'<div class="muted">±{100 * scale:.0f} %</div>'
        )
        cells += f'<td><img alt="test − reference" src="{difference_url}">{scale_text}</td>'
    else:
        cells += '<td class="muted">—</td>'
    cells += f'<td><img alt="p-value map" src="{pmap}"></td>' if pmap else '<td class="muted">—</td>'
    difference = _difference_cell(record)
    report = f'<a href="{html.escape(record["report"])}">report</a>' if record["report"] else ""
    why = f'<div class="muted">{html.escape(outcome.case.why)}</div>' if outcome.case.why else ""
    return (
        f'<tr class="case" data-status="{outcome.status}"><td><b>{html.escape(outcome.case.name)}</b>{why}</td>'
        f"<td>{html.escape(outcome.device)}</td>"
        f'<td class="status" style="color:{colour}" title="{STATUSES[outcome.status].meaning}">{outcome.status}</td>'
        f"{cells}"
        f'<td>{html.escape(outcome.verdict or "")}<div class="muted">{html.escape(outcome.message)}</div></td>'
        f'<td>{difference}</td><td class="num">{outcome.passes or ""}</td>'
        f'<td class="num">{outcome.seconds:.1f}</td><td>{report}</td></tr>'
    )


def _difference_cell(record: dict) -> str:
    """The whole image's difference and the largest tile difference, each with its interval (the largest's
    simultaneous over every tile: it was chosen for its size), as the verdict's outcome has them."""
    rows = []
    whole, largest = record.get("whole_image"), record.get("largest")
    if whole is not None and whole["estimate"] is not None:
        rows.append(f"whole image {html.escape(fmt.difference(whole))}")
    if largest is not None:
        rows.append(
            f'<div class="muted">largest tile {html.escape(fmt.difference(largest))} ({largest["channel"]} at '
            f"{largest['x']}, {largest['y']}, {largest['tile']} px; {largest['confidence']:.0%} simultaneous)</div>"
        )
    return "".join(rows) or "—"


def _ab(shown: str | None, other: str | None, name: str) -> str:
    """A render's cell: the other side's render under the pointer (A/B), when there is one."""
    if not shown:
        return '<td class="muted">—</td>'
    if not other:
        return f'<td><img alt="{name}" src="{shown}"></td>'
    return (f'<td><span class="ab" title="{name}; hover: the other side"><img class="shown" alt="{name}" '
            f'src="{shown}"><img class="other" alt="the other side" src="{other}"></span></td>')  # fmt: skip


def _thumbnails(outcome, reference: Path) -> tuple:
    """Data URLs of the reference's and the test side's mean renders, of their difference (and its scale) and of
    the p-value map (None: missing)."""
    if outcome.folder is None:
        return None, None, None, 0.0, None
    folder = Path(outcome.folder)
    means = []
    for path in (reference, folder / "test.npz"):
        try:
            preview, run = wc.load_preview(path), wc.load_stats(path, pixels=False)
        except wc.WelchInputError:
            preview = None
        means.append(None if preview is None or not run.n else wc.shrink(preview, THUMBNAIL) / np.float32(run.n))
    scale = wc.exposure(means[0]) if means[0] is not None else None
    urls: list[str | None] = [None if m is None else wc.png.data_url(wc.tonemap(m, scale=scale)) for m in means]
    difference, limit = (None, 0.0) if any(m is None for m in means) else wc.difference_picture(*means)
    difference_url = None if difference is None else wc.png.data_url(difference, wc.colormap.DIFFERENCE_PALETTE)
    return *urls, difference_url, limit, pvalue_thumbnail(folder)


def pvalue_thumbnail(folder: Path) -> str | None:
    """The data URL of the p-value map of the report in `folder` (log scale), None where there is none."""
    try:
        p = wc.read_exr(Path(folder) / "pvalues.exr").astype(float)
    except (OSError, wc.WelchInputError):
        return None
    p[p < 0] = np.nan  # the report writes untested tile-channels as -1
    return wc.png.data_url(wc.colorize(wc.colormap.map_values(p, "log10")))
