"""Chart 2: the p-value methods, time per million tile-channel tests against their largest relative error.

Methods: the exact Student t (welch_core's default), the paper's Gaussian (eq. 5) and its Abramowitz-Stegun erf
(eq. 6), each once where nu >= 20 only (what welch_core offers) and once everywhere (what the paper warns about in
§5.7). Reference: mpmath at 40 digits on a grid of nu in [1, 1e4] (log-spaced) and |t| in [0, 40]. Relative errors
are taken where the true p is at least 1e-300 (doubles hold nothing smaller); the error of log p is taken where
p < 0.01, the region that decides a verdict.
"""

from __future__ import annotations

from pathlib import Path

import mpmath
import numpy as np
from matplotlib.ticker import NullFormatter
from scipy import special

import welch_core as wc

from ..common.cache import digest, memo_json
from ..common.measure import best_time, mp_student
from ..common.plotting import plt, save, write_csv
from ..common.pools import say
from ..common.words import gauss_fp as _gauss_fp

METHODS = {
    "exact": ("exact Student t", lambda t, nu: wc.two_sided_pvalue(t, nu, "exact")),
    "gauss_nu20": ("Gaussian where ν ≥ 20", lambda t, nu: wc.two_sided_pvalue(t, nu, "gauss")),
    "as_erf_nu20": ("A&S erf where ν ≥ 20", lambda t, nu: wc.two_sided_pvalue(t, nu, "as_erf")),
    "gauss_all": ("Gaussian everywhere", lambda t, _nu: wc.pvalue_gauss(t)),
    "as_erf_all": ("A&S erf everywhere", lambda t, _nu: wc.pvalue_as_erf(t)),
}
SMALL_P = 0.01
FLOOR = 1e-300
#: Below this no verdict changes: alpha = 0.01 over 3 channels and 10^4 tiles (Bonferroni/Holm) is 3e-7.
DECISIVE = 1e-7


def reference(n_nu: int, n_t: int, cache_dir: Path) -> dict:
    """log10 of the true two-sided p on the grid, from mpmath at 40 digits (cached: it takes a while)."""

    def compute():
        nu = np.logspace(0, 4, n_nu)
        t = np.linspace(0, 40, n_t)
        with mpmath.workdps(40):
            logp = [[float(mpmath.log10(mp_student(float(a), float(d)))) for a in t] for d in nu]
        return {"nu": nu.tolist(), "t": t.tolist(), "log10p": logp}

    return memo_json(cache_dir, "pvalue-reference", digest(n_nu, n_t, 40), compute)


#: True p-values at which the per-nu curves show each method's error: alpha of one test, and a Holm threshold.
LEVELS = (1e-2, 1e-5)


def errors(ref: dict) -> tuple[dict, dict]:
    """Per method: the largest relative error of p and of log p; and per nu, the relative error at LEVELS."""
    nu, t = np.meshgrid(ref["nu"], ref["t"], indexing="ij")
    log10_true = np.array(ref["log10p"])
    true = 10.0**log10_true
    ok = log10_true >= np.log10(FLOOR)
    small = ok & (log10_true < np.log10(SMALL_P))
    worst, per_nu = {}, {}
    for name, (_label, f) in METHODS.items():
        with np.errstate(divide="ignore", invalid="ignore"):
            p = f(t, nu)
            rel = np.abs(p - true) / true
            rel_log = np.abs(np.log10(p) - log10_true) / np.abs(log10_true)
        decisive = log10_true >= np.log10(DECISIVE)
        worst[name] = {
            "rel_p": float(rel[ok].max()),
            "rel_p_decisive": float(rel[decisive].max()),
            "rel_logp": float(rel_log[small].max()),
        }
    nu = np.logspace(0, 4, 200)
    for level in LEVELS:
        t = -special.stdtrit(nu, level / 2)  # |t| whose exact two-sided p is `level`
        for name, (_label, f) in METHODS.items():
            per_nu[f"{name}@{level:g}"] = (f(t, nu) / level - 1).tolist()
    per_nu["nu"] = nu.tolist()
    return worst, per_nu


def timings(size: int) -> dict[str, float]:
    """Milliseconds per million tile-channel tests (best of 5; t uniform in ±40, nu log-uniform in [1, 1e4])."""
    rng = np.random.default_rng(3)
    t = rng.uniform(-40.0, 40.0, size)
    nu = 10.0 ** rng.uniform(0.0, 4.0, size)
    return {name: best_time(lambda f=f: f(t, nu), 5) * 1e3 * 1e6 / size for name, (_l, f) in METHODS.items()}


def run(b, cache_dir: Path, out_dir: Path) -> dict:
    say("chart 2: mpmath reference")
    ref = reference(*b.pvalue_grid, cache_dir)
    worst, per_nu = errors(ref)
    say("chart 2: timing")
    ms = timings(b.pvalue_size)
    rows = [
        {"method": name, "label": METHODS[name][0], "ms_per_million": ms[name], "max_rel_err_p": worst[name]["rel_p"],
         "max_rel_err_p_decisive": worst[name]["rel_p_decisive"], "max_rel_err_log_p_small": worst[name]["rel_logp"]}
        for name in METHODS
    ]  # fmt: skip
    files = [
        write_csv(out_dir / "chart2_pvalue_methods.csv", rows),
        _plot(out_dir / "chart2_pvalue_methods.png", rows, ref, per_nu),
    ]
    return {"files": files, "rows": rows, "grid": {"nu": len(ref["nu"]), "t": len(ref["t"])}, "at": error_table()}


def error_table(nus=(2, 5, 10, 20, 100), levels=LEVELS) -> list[dict]:
    """Relative error of each method's p where the exact p is `level`, at a few nu (for docs/benchmarks/README.md)."""
    out = []
    for nu in nus:
        for level in levels:
            t = -special.stdtrit(float(nu), level / 2)
            row = {"nu": nu, "p": level, "t": float(t)}
            row |= {
                name: float(f(np.array([t]), np.array([float(nu)]))[0] / level - 1) for name, (_l, f) in METHODS.items()
            }
            out.append(row)
    return out


def _plot(path: Path, rows: list[dict], ref: dict, per_nu: dict) -> str:
    fig, axes = plt.subplots(1, 4, figsize=(21, 4.6))
    cap = 1e3  # where an infinite error (p underflowed to 0) is drawn
    for ax, key, title in (
        (axes[0], "max_rel_err_p", "largest relative error of p (p ≥ 1e-300)"),
        (axes[1], "max_rel_err_p_decisive", f"largest relative error of p (p ≥ {DECISIVE:g}: decides verdicts)"),
        (axes[2], "max_rel_err_log_p_small", f"largest relative error of log p (p < {SMALL_P})"),
    ):
        for i, r in enumerate(rows):
            y = r[key] if np.isfinite(r[key]) else cap
            ax.plot(r["ms_per_million"], max(y, 1e-17), "^" if y == cap else "o", color=f"C{i}", ms=8, label=r["label"])
            point = (r["ms_per_million"], max(y, 1e-17))
            text = "∞" if y == cap else f"{y:.1e}"
            ax.annotate(text, point, xytext=(6, -3 - 9 * (i % 2)), textcoords="offset points", fontsize=8)
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(NullFormatter())  # the default labels every minor tick: unreadable
        ax.set_xticks([3, 10, 30, 100, 300], ["3", "10", "30", "100", "300"])
        ax.set_xlim(3, 600)
        ax.set_yscale("log")
        ax.set_xlabel("ms per million tile-channel tests")
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3, which="both", lw=0.4)
    axes[0].legend(fontsize=8, loc="center right")
    for i, name in enumerate(METHODS):
        for level, style in zip(LEVELS, ("-", "--"), strict=True):
            values = np.abs(per_nu[f"{name}@{level:g}"])
            axes[3].plot(per_nu["nu"], np.maximum(values, 1e-17), style, color=f"C{i}")
    for level, style in zip(LEVELS, ("-", "--"), strict=True):
        axes[3].plot([], [], style, color="k", label=f"at true p = {level:g}")
    axes[3].legend(fontsize=8)
    axes[3].axvline(20, color="k", ls=":", lw=0.8)
    axes[3].set_xscale("log")
    axes[3].set_yscale("log")
    axes[3].set_xlabel("degrees of freedom ν")
    axes[3].set_title("|relative error of p| at a given true p, per ν", fontsize=10)
    axes[3].grid(alpha=0.3, which="both", lw=0.4)
    fig.suptitle(
        f"Chart 2: p-value methods (reference: mpmath, 40 digits, {len(ref['nu'])} ν × {len(ref['t'])} |t| grid)"
    )
    return save(fig, path)


# -- its section of docs/benchmarks/README.md --------------------------------------------------------------------------


def section(f: dict) -> list[str]:
    """Chart 2's section of docs/benchmarks/README.md from the figures `f`."""
    parts = [CHART2.format(nu=f["chart2"]["grid"]["nu"], t=f["chart2"]["grid"]["t"])]
    return parts + chart2_lines(f["chart2"]) + [""] + chart2_findings(f["chart2"], f.get("chart1"))


CHART2 = """
## Chart 2: p-value methods, time against error

![chart 2](chart2_pvalue_methods.png)

Reference: mpmath at 40 digits on {nu} values of ν (log-spaced in [1, 10⁴]) × {t} values of |t| in [0, 40].
Timing: one million tile-channel tests with |t| uniform in [0, 40] and ν log-uniform, best of 5.
"""


def chart2_lines(c2: dict) -> list[str]:
    lines = ["| method | ms per million tests | max rel. error of p | same, p ≥ 1e-7 "
             "| max rel. error of log p, p < 0.01 |",
             "|---|---|---|---|---|"]  # fmt: skip
    for r in c2["rows"]:
        lines.append(
            f"| {r['label']} | {r['ms_per_million']:.0f} | {r['max_rel_err_p']:.2g} "
            f"| {r['max_rel_err_p_decisive']:.2g} | {r['max_rel_err_log_p_small']:.2g} |"
        )
    return lines


def chart2_findings(c2: dict, c1: dict | None = None) -> list[str]:
    rows = {r["method"]: r for r in c2["rows"]}
    ex, g20, gall, aall = rows["exact"], rows["gauss_nu20"], rows["gauss_all"], rows["as_erf_all"]
    at = {(r["nu"], r["p"]): r for r in c2["at"]}
    a5, a20 = at.get((5, 0.01)), at.get((20, 1e-05))
    out = [
        f"- **Exact Student t** (the default): largest relative error of p {ex['max_rel_err_p']:.1g} over the whole "
        f"grid, of log p {ex['max_rel_err_log_p_small']:.1g}, at {ex['ms_per_million']:.0f} ms per million "
        "tile-channel tests: a 4K frame at 32² tiles has 24 120 tile-channels, so the exact p costs a few "
        "milliseconds a verdict. There is nothing to gain from an approximation.",
        f"- **Gaussian where ν ≥ 20** ('gauss'): {g20['ms_per_million']:.0f} ms per million, "
        + (
            "no faster than the exact p (welch_core evaluates the exact p everywhere, then replaces it where ν ≥ 20). "
            if g20["ms_per_million"] > 0.8 * ex["ms_per_million"]
            else f"{ex['ms_per_million'] / g20['ms_per_million']:.1f}× faster than the exact p. "
        )
        + f"Its largest relative error among p ≥ 1e-7 on the grid is {g20['max_rel_err_p_decisive']:.2g}"
        + (f"; at ν = 20, where the exact p is 1e-5, it gives {1e-5 * (1 + a20['gauss_nu20']):.2g}" if a20 else "")
        + ": the tails of t with 20 degrees of freedom are far heavier than the Gaussian's, so at the small p that "
        "Holm's correction compares against the approximation is anti-conservative." + (_gauss_fp(c1) if c1 else ""),
        f"- **Gaussian / A&S everywhere**: {gall['ms_per_million']:.0f} and {aall['ms_per_million']:.0f} ms per "
        f"million ({ex['ms_per_million'] / gall['ms_per_million']:.0f}× and "
        f"{ex['ms_per_million'] / aall['ms_per_million']:.0f}× faster than exact), but wrong where ν is small"
        + (
            f" (at ν = 5, where the exact p is 0.01, the Gaussian gives {0.01 * (1 + a5['gauss_all']):.2g})"
            if a5
            else ""
        )
        + " and underflowing to 0 in the far tail (infinite error of log p). Chart 3 shows what that does to the "
        "false-positive rate.",
    ]
    return out
