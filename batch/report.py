"""The report of a comparison: report.json, p-value maps (PNG at image size, float EXR at tile size), the overlay
on the tone-mapped mean image, the p-value histogram (paper Fig. 10), per-channel maps, the effect-size map and a
one-page report.html showing them side by side with the verdict.
"""

from __future__ import annotations

import html
import json
import os
from pathlib import Path

import numpy as np

from . import fmt
from ._siblings import welch_core as wc

#: Few-bins histogram: at low sample counts it shows bias best (paper Fig. 16f).
FEW_BINS = 5


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def write_report(
    out_dir: str | os.PathLike,
    summary: dict,
    result: wc.Comparison,
    ref: wc.TileStats,
    test: wc.TileStats,
) -> dict:
    """Write every output of a comparison into `out_dir` (created if missing); return the report dict (the
    summary of `batch.summary.summarize` and the files written)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report = dict(summary, files={})
    files = report["files"]
    plt = _pyplot()
    files["pvalue_map_png"] = _save_rgb(out / "pvalue_map.png", _full_map(result))
    wc.write_exr(out / "pvalues.exr", np.nan_to_num(result.pvalues, nan=-1.0))
    files["pvalues_exr"] = "pvalues.exr"
    files["overlay_png"] = _overlay_figure(
        plt, out / "overlay.png", result, test if test.mean_image is not None else ref
    )
    files["histogram_png"] = _histogram_figure(plt, out / "histogram.png", result)
    files["channels_png"] = _channels_figure(plt, out / "channels.png", result)
    files["effect_png"] = _effect_figure(plt, out / "effect.png", result)
    report["files"] = files
    write_text(out / "report.json", json.dumps(report, indent=2, allow_nan=False))
    write_text(out / "report.html", _html(report))
    return report


def _save_figure(fig, path: Path, **options) -> None:
    wc.formats.atomic_write(path, lambda f: fig.savefig(f, format="png", dpi=100, **options))


def write_text(path: Path, text: str) -> None:
    """Write a text file atomically (a failure leaves the previous file and raises)."""
    wc.formats.atomic_write(path, lambda f: f.write(text.encode("utf-8")))


def _full_map(result: wc.Comparison, mode: str = "min") -> np.ndarray:
    tiles = wc.pvalue_rgb(result, mode)
    return wc.upscale_tiles(tiles, result.tile, result.height, result.width, fill=wc.colormap.EXCLUDED_GREY)


def _save_rgb(path: Path, rgb: np.ndarray) -> str:
    plt = _pyplot()
    wc.formats.atomic_write(path, lambda f: plt.imsave(f, np.clip(rgb, 0.0, 1.0), format="png"))
    return path.name


def _legend(plt, fig, ax) -> None:
    import matplotlib as mpl

    norm = mpl.colors.Normalize(0.0, 1.0)
    bar = fig.colorbar(mpl.cm.ScalarMappable(norm=norm, cmap="viridis_r"), ax=ax, fraction=0.046, pad=0.02)
    bar.set_label("p-value (smallest over channels)")


def _overlay_figure(plt, path: Path, result: wc.Comparison, run: wc.TileStats, opacity: float = 0.6) -> str:
    base = wc.tonemap(run.mean_image) if run.mean_image is not None else np.full((run.height, run.width, 3), 0.5)
    tiles_rgb = wc.pvalue_rgb(result, "min")
    mask = wc.upscale_tiles(np.isfinite(result.tile_pvalues), result.tile, result.height, result.width, fill=False)
    image = wc.overlay(base, wc.upscale_tiles(tiles_rgb, result.tile, result.height, result.width), opacity, mask)
    fig, ax = plt.subplots(figsize=(6, 6 * run.height / run.width + 0.3))
    ax.imshow(np.clip(image, 0, 1), interpolation="nearest")
    _mark_significant(plt, ax, result)
    ax.set_title(f"p-value map over the mean render ({result.verdict.text})")
    ax.axis("off")
    _legend(plt, fig, ax)
    _save_figure(fig, path, bbox_inches="tight")
    plt.close(fig)
    return path.name


def _mark_significant(plt, ax, result: wc.Comparison) -> None:
    """Outline the tiles that are significant after the family-wise correction."""
    for row, col in zip(*np.nonzero(result.significant), strict=True):
        t = result.tile
        ax.add_patch(plt.Rectangle((col * t - 0.5, row * t - 0.5), t, t, fill=False, edgecolor="red", lw=1.2))


def _histogram_figure(plt, path: Path, result: wc.Comparison) -> str:
    p = result.pvalues[result.used]
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.2), gridspec_kw={"width_ratios": [3, 1]})
    for ax, bins in zip(axes, (30, FEW_BINS), strict=True):
        counts, edges, expected = wc.histogram(p, bins)
        ax.bar(edges[:-1], counts, width=np.diff(edges), align="edge", color="tab:blue", edgecolor="white")
        ax.axhline(expected, color="black", ls="--", lw=1, label="uniform (no bias)")
        if p.size:
            ax.plot([p.mean()], [0], marker="^", color="red", ms=10, clip_on=False, label=f"mean {p.mean():.3f}")
        ax.set_xlim(0, 1)
        ax.set_xlabel("p-value")
        ax.set_title(f"{bins} bins")
    axes[0].set_ylabel("tile-channels")
    axes[0].legend(loc="upper right", fontsize=8)
    fig.suptitle(f"p-values of {p.size} tile-channels; global p {fmt.p_is(result.p_value)}", fontsize=10)
    fig.tight_layout()
    _save_figure(fig, path)
    plt.close(fig)
    return path.name


def _channels_figure(plt, path: Path, result: wc.Comparison) -> str:
    channels = result.pvalues.shape[-1]
    fig, axes = plt.subplots(1, channels, figsize=(3.2 * channels, 3.2 * result.height / result.width + 0.4))
    for ch, ax in enumerate(np.atleast_1d(axes)):
        ax.imshow(wc.pvalue_rgb(result, "channel", ch), interpolation="nearest")
        ax.set_title(f"channel {'RGB'[ch] if channels == 3 else ch}")
        ax.axis("off")
    fig.tight_layout()
    _save_figure(fig, path)
    plt.close(fig)
    return path.name


def _effect_figure(plt, path: Path, result: wc.Comparison) -> str:
    valid = result.reasons == wc.Reason.VALID
    with np.errstate(invalid="ignore"):  # tiles with no valid channel stay NaN (blank)
        rel = np.where(valid, result.effect.rel_diff, 0.0).sum(axis=-1) / valid.sum(axis=-1) * 100
    limit = np.nanmax(np.abs(rel)) if np.isfinite(rel).any() else 1.0
    fig, ax = plt.subplots(figsize=(5, 5 * result.height / result.width + 0.3))
    shown = ax.imshow(rel, cmap="RdBu_r", vmin=-limit, vmax=limit, interpolation="nearest")
    ax.set_title("relative difference of tile means, test vs reference (%)")
    ax.axis("off")
    fig.colorbar(shown, ax=ax, fraction=0.046, pad=0.02, label="%")
    _save_figure(fig, path, bbox_inches="tight")
    plt.close(fig)
    return path.name


def _html(report: dict) -> str:
    esc = html.escape
    files = report["files"]
    colour = {"biased": "#b00020", "equivalent": "#1b7f3b", "no_evidence": "#1b7f3b", "inconclusive": "#a06000"}[
        report["verdict"]
    ]
    rows = "".join(
        f"<tr><td>{t['x']},{t['y']}</td><td>{t['channel']}</td><td>{fmt.p_value(t['pvalue'])}</td>"
        f"<td>{fmt.p_value(t['qvalue'])}</td><td>{'yes' if t['significant'] else 'no'}</td>"
        f"<td>{fmt.percent(t['rel_diff'])} [{fmt.percent(t['ci_low'])}, {fmt.percent(t['ci_high'])}]</td></tr>"
        for t in report["top_tiles"]
    )
    selftest = report["reference_selftest"]
    checks = [f"differs: {d}" for d in report["differences"]]
    if selftest is not None:
        checks.append(
            f"the reference against itself (two halves of {report['n_ref']} passes): "
            f"{wc.Verdict(selftest['verdict']).text}, p {fmt.p_is(selftest['p_value'])}"
        )
    notes = "".join(f"<li>{esc(n)}</li>" for n in report["notes"] + report["warnings"] + checks)
    excluded = ", ".join(f"{esc(k)}: {v}" for k, v in report["tile_channels"].items())
    images = "".join(
        f'<figure><img src="{esc(files[k])}" alt="{esc(label)}"><figcaption>{esc(label)}</figcaption></figure>'
        for k, label in (
            ("overlay_png", "p-value map over the mean render (red: significant after correction)"),
            ("histogram_png", "histogram of p-values (30 and 5 bins)"),
            ("channels_png", "p-value map per channel"),
            ("effect_png", "relative difference of tile means"),
            ("pvalue_map_png", "p-value map (smallest p over channels)"),
        )
    )
    return f"""<!doctype html>
<html><head><meta charset="utf-8"><title>Bias test: {esc(report["verdict"])}</title>
<style>body{{font-family:sans-serif;margin:1.5em;max-width:1400px}} .verdict{{font-size:1.6em;color:{colour}}}
figure{{display:inline-block;margin:.5em;vertical-align:top}} img{{max-width:640px;image-rendering:pixelated}}
table{{border-collapse:collapse}} td,th{{border:1px solid #ccc;padding:2px 8px;text-align:right}}</style></head>
<body><h1>Does the test run converge to the reference image?</h1>
<p class="verdict">{esc(report["verdict_text"])}</p>
<p>alpha = {report["alpha"]:g}, global p {fmt.p_is(report["p_value"])} ({esc(report["method"])}).<br>
Reference: {esc(report["reference"]["name"])}, n = {report["n_ref"]} passes (seeds {esc(report["reference"]["seeds"])});
test: {esc(report["test_run"]["name"])}, n = {report["n_test"]} passes (seeds {esc(report["test_run"]["seeds"])}).<br>
Tiles: {report["tiles"]["used"]} used of {report["tiles"]["total"]}, {report["tiles"]["untrusted"]} untrusted,
{report["tiles"]["significant"]} significant. Tile-channels by reason: {excluded}.</p>
<ul>{notes}</ul>
{images}
<h2>Most significant tiles</h2>
<table><tr><th>x,y</th><th>channel</th><th>p</th><th>q</th><th>significant</th><th>test vs reference (CI)</th></tr>
{rows}</table>
</body></html>
"""
