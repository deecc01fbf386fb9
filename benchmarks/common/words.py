"""The words of the benchmark charts: how their figures are written in docs/benchmarks/README.md."""

from __future__ import annotations

from .trials import FIXED_WELCH

WELCH = FIXED_WELCH


def s(x) -> str:
    if x is None:
        return "not reached"
    return f"{x:.2g} s" if x < 10 else f"{x:.0f} s"


def p(x: float) -> str:
    if x != x:
        return "—"
    return "< 1e-300" if x == 0 else f"{x:.2g}"


def pct(x: float, digits: int = 1) -> str:
    return f"{100 * x:.{digits}f} %"


def best(summary: list[dict], case: str, methods) -> tuple[str | None, float | None]:
    found = [(r["seconds_to_80"], methods.index(r["method"]), r["method"]) for r in summary
             if r["case"] == case and r["method"] in methods and r["seconds_to_80"] is not None]  # fmt: skip
    if not found:
        return None, None
    s, _order, m = min(found)  # a tie goes to the first of `methods` (the smallest tile)
    return m, s


def cell(rows: dict, method: str) -> str:
    """Seconds to 80 % of a method, or '—' where it did not run (a tile larger than the image)."""
    return s(rows[method]["seconds_to_80"]) if method in rows else "—"


def tile(method: str) -> str:
    return {"16": "16²", "32": "32²", "64": "64²", "128": "128²"}.get("".join(filter(str.isdigit, method)), method)


def x(x) -> str:
    return "—" if x is None else f"{x:.2f}×"


def n(x) -> str:
    return "—" if x is None else f"{x:.0f}"


MODE_NAMES = {"paired": "paired", "unpaired": "unpaired"}


def rate(r: dict, prefix: str = "") -> str:
    return f"{pct(r[prefix + 'rate'])} [{pct(r[prefix + 'lo'])}, {pct(r[prefix + 'hi'])}]"


def tg(t) -> str:
    if t is None:
        return "∞"
    return f"{t:.3g}" if t < 1000 else f"{t:.2g}"


def gauss_fp(c1: dict) -> str:
    fp = {(r["group"], r["method"]): r for r in c1["false_positives"]}
    pairs = [(g, fp[(g, "welch32")], fp[(g, "gauss32")]) for g, m in fp if m == "gauss32" and (g, "welch32") in fp]
    text = ", ".join(f"{g} {pct(w['rate'])} → {pct(x['rate'])}" for g, w, x in pairs)
    return f" On unbiased pairs (chart 1) it moved the false-positive rate at 32² tiles from exact to Gaussian: {text}."


def fine_share(rows: list[dict]) -> str:
    """'99–100 % from 16 passes a side on (0 % at 8)': the inconclusive share of one tile size alone."""
    high = [r for r in rows if r["inconclusive_share"] >= 0.95]
    if not high:
        return f"at most {pct(max(r['inconclusive_share'] for r in rows), 0)}"
    start = min(r["n"] for r in high)
    later = [r["inconclusive_share"] for r in rows if r["n"] >= start]
    text = f"{pct(min(later), 0)}–{pct(max(later), 0)} from {start} passes a side on"
    earlier = sorted({r["n"] for r in rows if r["n"] < start})
    if earlier:
        shares = [f"{pct(max(r['inconclusive_share'] for r in rows if r['n'] == n), 0)} at {n}" for n in earlier]
        text += f" (at most {', '.join(shares)})"
    return text
