"""The page of an audit (`batch.decide.audit_run`): one self-contained ``index.html`` in the suite dashboard's look.
At the top, what the audit found: each confirmed difference of a setting documented to change only the noise, with
its effect, its explanation (the change with the biased-by-design settings off, the light component that carries
it, the release it first appears in) and the command that reproduces it; then the controls, and how alpha was
split. Below, the settings x scenes table: each cell's verdict, its effect with its interval (or the claim of
`equivalent`: the tolerance and the tile size), passes and seconds, linked to its report. It decides nothing:
every word comes from the cells' records."""

from __future__ import annotations

import html

from .._siblings import welch_core as wc
from ..errors import Exit
from ..jobs.protocol import CaseStatus
from . import fmt
from .dashboard import STYLE
from .statuses import STATUS_COLOURS

#: Each status's colour and word, for a cell of a change documented to change only the noise, and of a control.
_CELL = {
    "biased": ("#b00020", "biased"),
    "unconfirmed": ("#a06000", "not confirmed"),
    "equivalent": (STATUS_COLOURS[CaseStatus.PASSED], "no difference"),
    "undecided": ("#a06000", "not decided"),
    "not_applicable": (STATUS_COLOURS[CaseStatus.SKIPPED], "not applicable"),
    "error": (STATUS_COLOURS[CaseStatus.ERROR], "error"),
}
_CONTROL = {
    "biased": (STATUS_COLOURS[CaseStatus.PASSED], "found"),
    "unconfirmed": ("#a06000", "not confirmed"),
    "equivalent": ("#777", "not exercised"),
    "undecided": ("#777", "not found"),
}

#: A confirmed difference no larger than float rounding (`batch.decide.audit_run.ROUNDING`).
_ROUNDING = ("#7a5c00", "biased, rounding only")

_EXTRA_STYLE = """
header .muted,main p.muted,main p{max-width:1000px}
th.change .muted{font-weight:400}
td.cell{min-width:120px;font-size:12px}
td.cell .status{font-size:11px}
td.cell .why{font-size:11px;color:#666;max-width:180px}
.findings li{margin-bottom:10px}
code{font-size:12px;background:#f0f0ee;padding:1px 4px;word-break:break-all}
section{margin-bottom:18px}
th.change{max-width:260px}
"""


def headline(summary: dict) -> str:
    """The audit's outcome in a few words (its exit code's meaning)."""
    findings = len(summary["findings"])
    rounding = len(summary.get("rounding", ()))
    scale = f" ({rounding} at the scale of float rounding)" if rounding else ""
    return {
        Exit.OK: f"no noise-only setting is confirmed biased beyond float rounding{scale}",
        Exit.BIASED: f"{findings} confirmed difference{'s' if findings != 1 else ''} of noise-only settings{scale}",
        Exit.USAGE: "a cell could not run",
        Exit.INCONCLUSIVE: "a control was found in no scene: the audit can't vouch for its power",
    }[summary["exit_code"]]


def write_audit_page(path, plan, summary: dict, results) -> None:
    """Write the audit page of `results` (`batch.decide.audit_run.CellResult`) with `summary` (summary.json's)."""
    release = summary["release"]
    version = release["version"] or release["label"]
    named = "" if summary["audit"] == "cycles" else f" ({summary['audit']})"
    title = f"Audit of Cycles {version}{named}: {headline(summary)}"
    counts = dict(summary["counts"])
    found = sum(r.found for r in results)  # a control's `biased` is the audit working, not a finding
    rounding = sum(r.rounding for r in results)
    counts["biased"] -= found + rounding
    shown = [(_CELL[k][0], f"{v} {_CELL[k][1]}") for k, v in counts.items() if v]
    shown += [(_ROUNDING[0], f"{rounding} biased at the scale of float rounding")] if rounding else []
    shown += [(_CONTROL["biased"][0], f"{found} control{'s' if found != 1 else ''} found")] if found else []
    counts = "".join(f'<span style="color:{colour}">{html.escape(text)}</span>' for colour, text in shown)
    seconds = f" · {fmt.duration(summary['seconds'])} in all" if summary.get("seconds") else ""
    page = f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<meta name="viewport" content="width=device-width, initial-scale=1"><style>{STYLE}{_EXTRA_STYLE}</style></head>
<body><header><h1 id="title">{html.escape(title)}</h1>
<div class="counts" id="counts">{counts}</div>
<div class="muted" id="release">{html.escape(release["label"])} · build {html.escape(str(release["build"]))} ·
{summary["cells_k"]} cells{seconds} · {html.escape(summary["budget"])}</div></header>
<main>{_findings(summary, results)}{_controls(plan, results)}
<section><h2>Every cell</h2>{_table(plan, results)}
<p class="muted">A row per setting change (what Cycles documents it to change; the samples per render its passes
render), a column per scene. <b>no difference</b>: `equivalent`, the claim within the tolerance in every tile of
the size given, at the audit's level, or every pass bit-identical on both sides in at least as many passes as rule
out a change that alters one pass in ten at that level; <b>biased</b>: biased on its first seeds and again on
fresh ones with the tile sums alone; <b>biased, rounding only</b>: confirmed, but no larger than float rounding in
any tile (listed apart, no finding); <b>not confirmed</b>: biased on the first seeds only; <b>not decided</b>:
neither within the budget (the bias it rules out where it bounds one; <i>identical so far</i> where every pass
was identical but fewer than that; <i>too few passes</i> where the time budget ended before two a side). A
control's cell says <b>found</b> where its bias was confirmed, and <b>not exercised</b> where the scene shows no
effect of it. Click a cell for its report.</p></section>
<section><h2>Budget and level</h2><p id="budget">{html.escape(_sentence(summary.get("equal_budget", "")))}</p>
<p id="alpha">{html.escape(summary["alpha_split"])}.</p></section>
</main></body></html>
"""
    wc.formats.atomic_write(path, lambda f: f.write(page.encode("utf-8")))


def _findings(summary: dict, results) -> str:
    findings = [r for r in results if r.finding]
    rounding = [r for r in results if r.rounding]
    tail = ""
    if rounding:
        items = "".join(
            f'<li data-key="{html.escape(r.cell.key)}"><b>{html.escape(r.cell.change.name)}</b> on '
            f"<b>{html.escape(r.cell.scene.label)}</b>: {html.escape(r.message)} · "
            f'<a href="{html.escape(r.confirm["report"])}">confirmation</a></li>'
            for r in rounding
        )
        tail = (f'<h3>At the scale of float rounding</h3><p class="muted">Confirmed, but no larger than float rounding '
                f"in any tile: the passes differ in their rounding, not in their light (a control here is one its "
                f'scene does not exercise).</p><ul id="rounding" class="findings">{items}</ul>')  # fmt: skip
    if not findings:
        return ('<section><h2>Findings</h2><p id="findings" class="findings">No setting documented to change only '
                f"the noise is confirmed biased beyond float rounding.</p>{tail}</section>")  # fmt: skip
    items = "".join(_finding(r) for r in findings)
    return f'<section><h2>Findings</h2><ol id="findings" class="findings">{items}</ol>{tail}</section>'


def _finding(result) -> str:
    cell, confirm, first = result.cell, result.confirm, result.first
    lines = [f"<b>{html.escape(cell.change.name)}</b> ({html.escape(cell.change.setting)}) on "
             f"<b>{html.escape(cell.scene.label)}</b>: {html.escape(result.message)}"]  # fmt: skip
    layers = (confirm or {}).get("layers")
    if layers and layers.get("explanation"):
        lines.append(f"light components: {html.escape(layers['explanation'])}")
    explain = result.explain or {}
    if "skipped" in explain:
        lines.append(f"biased-by-design settings: {html.escape(explain['skipped'])}")
    elif "meaning" in explain:
        link = f' (<a href="{html.escape(explain["report"])}">report</a>)'
        lines.append(f"biased-by-design settings off: {html.escape(explain['meaning'])}{link}")
    elif "error" in explain:
        lines.append(f"biased-by-design settings off: could not run: {html.escape(explain['error'])}")
    if result.bisect:
        bisect = result.bisect
        lines.append(f"releases: {html.escape(bisect.get('message') or bisect.get('error', ''))}")
    if result.command:
        lines.append(f"reproduce: <code>{html.escape(result.command)}</code>")
    links = f'<a href="{html.escape(first["report"])}">first check</a>'
    if confirm:
        links += f' · <a href="{html.escape(confirm["report"])}">confirmation</a>'
    lines.append(links)
    return f'<li class="finding" data-key="{html.escape(cell.key)}">' + "<br>".join(lines) + "</li>"


def _controls(plan, results) -> str:
    rows = []
    for change in plan.spec.changes:
        if not change.control:
            continue
        mine = [r for r in results if r.cell.change.name == change.name and r.status != "not_applicable"]
        found = [r.cell.scene.label for r in mine if r.found]
        where = f"found in {len(found)} of {len(mine)} scenes" + (f" ({', '.join(found)})" if found else "")
        for status, word in (("equivalent", "not exercised (no difference)"), ("rounding", "not exercised (float "
                             "rounding only)"), ("unconfirmed", "not confirmed"), ("undecided", "not decided"),
                             ("error", "could not run")):  # fmt: skip
            scenes = [r.cell.scene.label for r in mine if r.status == status or status == "rounding" and r.rounding]
            if scenes:
                where += f"; {word} in {', '.join(scenes)}"
        rows.append(f"<li><b>{html.escape(change.name)}</b>: {html.escape(where)}</li>")
    if not rows:
        return ""
    return ('<section><h2>Controls</h2><p class="muted">Settings biased by design: where none is found, the audit '
            f'could not have found a noise-only setting\'s bias either.</p><ul id="controls">{"".join(rows)}</ul>'
            "</section>")  # fmt: skip


def _table(plan, results) -> str:
    by = {(r.cell.change.name, r.cell.scene.label): r for r in results}
    scenes = [s.label for s in plan.spec.scenes]
    head = "".join(f"<th>{html.escape(s)}</th>" for s in scenes)
    rows = []
    for change in plan.spec.changes:
        what = "biased by design (a control)" if change.control else "changes only the noise"
        what = "the scene against itself, disjoint seeds" if change.aa else what
        label = (f'<th class="change"><b>{html.escape(change.name)}</b><div class="muted">{html.escape(what)}; '
                 f"{change.samples} sample{'s' if change.samples > 1 else ''} a pass<br>"
                 f"{html.escape(change.why)}</div></th>")  # fmt: skip
        cells = "".join(_cell(by.get((change.name, s))) for s in scenes)
        rows.append(f'<tr data-change="{html.escape(change.name)}">{label}{cells}</tr>')
    head = f"<thead><tr><th>setting \\ scene</th>{head}</tr></thead>"
    return f'<table id="cells">{head}<tbody>{"".join(rows)}</tbody></table>'


def _cell(result) -> str:
    if result is None:
        return '<td class="muted">—</td>'
    table = _CONTROL if result.cell.change.control and result.status in _CONTROL else _CELL
    colour, word = _ROUNDING if result.rounding else table[result.status]
    first, confirm = result.first, result.confirm
    shown = confirm if result.status == "biased" else first
    body = [f'<div class="status" style="color:{colour}">{html.escape(word)}</div>']
    if result.status == "equivalent" and first.get("identical"):
        body.append(f"<div>identical in all {first['passes']} passes</div>")
    elif result.status == "equivalent":
        body.append(f"<div>{html.escape(_claim(first))}</div>")
    elif result.status == "undecided" and first is not None and first.get("identical"):
        needed = first.get("identical_needed") or wc.identical_passes(first["alpha"])
        body.append(f'<div class="why">identical so far: {first["passes"]} of the {needed} passes that rule out a '
                    "change altering one pass in ten</div>")  # fmt: skip
    elif shown is not None and shown.get("whole_image") and shown["whole_image"].get("estimate") is not None:
        body.append(f"<div>{html.escape(fmt.difference(shown['whole_image']))}</div>")
    strongest = (shown or {}).get("most_significant")
    if result.rounding:
        body.append('<div class="why">no larger than float rounding in any tile</div>')
    elif result.status == "biased" and strongest and strongest.get("tile"):
        where = f"{strongest['channel']} of a {strongest['tile']}² tile at {strongest['x']}, {strongest['y']}"
        body.append(f'<div class="muted">most significant: {html.escape(fmt.difference(strongest))} in {where}</div>')
    if first is None and result.status in ("undecided", "error"):
        why = result.message.removeprefix("error: ")
        why = "too few passes within the budget" if result.status == "undecided" else why
        body.append(f'<div class="why">{html.escape(why if len(why) <= 160 else why[:157] + "…")}</div>')
    if result.status == "undecided" and first and first.get("ruled_out"):
        ruled = first["ruled_out"]
        body.append(f'<div class="muted">±{fmt.bound(ruled["bias"])} ruled out per {ruled["tile"]}² tile</div>')
    if first is not None:
        passes = f"{first['passes']}" + (f" + {confirm['passes']}" if confirm else "")
        body.append(f'<div class="muted">{passes} passes · {result.seconds:.0f} s</div>')
        link = f'<a href="{html.escape(first["report"])}">report</a>'
        if confirm:
            link += f' · <a href="{html.escape(confirm["report"])}">confirmation</a>'
        body.append(f"<div>{link}</div>")
    title = html.escape(result.message)
    return (f'<td class="cell" data-status="{result.status}" data-key="{html.escape(result.cell.key)}" '
            f'title="{title}">{"".join(body)}</td>')  # fmt: skip


def _sentence(text: str) -> str:
    return text[:1].upper() + text[1:] + "." if text else ""


def _claim(record: dict) -> str:
    tolerance, tile = record.get("tolerance"), record.get("claim_tile")
    within = f"within ±{100 * tolerance:.2f} %" if tolerance else "within the tolerance"
    return f"{within} per {tile}² tile" if tile else within
