"""A tile's variance from its pixels: the pixel-variance test, where a renderer's pixels are independent.

The tile test estimates Var(tile sum) from the n tile sums of each side: n - 1 degrees of freedom, so at 2-4
passes a side its critical values are enormous. Cycles samples every pixel on its own (filter importance sampling,
no splatting, a scrambled sequence per pixel), so where the pixels of a pass are independent

    Var(tile sum) = sum over the tile's pixels p of Var(pixel p)                                       (1)

and each pixel's sample variance s_p² over the passes estimates its term. Per tile-channel, with m the side's mean
tile sum and V = sum_p s_p² (`PixelMoments` keeps each pixel's mean and M2, streaming and mergeable):

    t = (m_test - m_ref) / sqrt(V_ref / n_ref + V_test / n_test)                                    (2)
    df = (V_ref / n_ref + V_test / n_test)² / sum_sides (Q / (n² (n - 1))),  Q = sum_p (s_p²)²        (3)

(3) is Satterthwaite's for a sum of independent variance estimates, each with n - 1 degrees of freedom: up to
tile² (n - 1), so at n = 2 the critical value is nearly normal instead of that of a t with one degree of freedom.

A pixel that takes few values (a light seen or not, a caustic hit or not) has a sample variance of exactly 0 on a
side whose few passes happened to agree, so V can miss the very pixels that make the sides' means differ
(measured: a glass caustic's pixel of 76.4 in both of one side's two passes, 0 in the other's, gave |t| = 62).
Under H0 a pixel has one mean on both sides, so its variance over both sides' passes together is as good an
estimate, and it sees such a pixel whatever its passes did:

    se² = max(V_ref / n_ref + V_test / n_test, V_both (1 / n_ref + 1 / n_test))                       (4)

with V_both = sum_p of each pixel's variance over all n_ref + n_test passes (its df (3) with n_ref + n_test - 1 a
pixel), while the smaller side has at most `POOLED_UP_TO` passes. Under H1 V_both also holds each pixel's
difference, which grows against the noise with the passes: past a few passes it would cost the power it exists
to keep, and chance agreement has become rare. Paired runs test the per-seed differences d the same way: V / n,
or the second moments about 0 (sum_p sum d² / n, n df a pixel; unbiased under H0, where each pixel's d has mean
0) where larger.

Hypothesis and family: per tile-channel H0 is that the two sides' expected tile sums are equal, as for the tile
test; the pixel test replaces the tile test's p-value of a tile-channel and the family (`comparison`, `looks`) is
unchanged. Its assumption, (1), is not tested by the data at a few passes, so it is used only where the run's own
record proves the settings under which it was measured (`pixel_eligibility`), and refused where the data contradict it
grossly (`tripwire`) or the moments can't be those of the tile sums' passes (`moment_conflict`). Where (3) is
small the tile's pixels are skewed (a few pixels carry the tile) and Satterthwaite's df, which assumes normal
pixels, overstates the evidence: below `MIN_PIXEL_DF` a tile-channel keeps the tile test (measured:
docs/findings/pixel_variance.md).

numpy only (scipy where a p-value is computed): the moments are accumulated inside a stock Blender.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from . import parallel
from .errors import WelchInputError
from .ttest import Reason, TTestResult, paired_from_stats, two_sided_pvalue, welch_from_stats

__all__ = [
    "INDEPENDENT_PATTERNS",
    "LOCAL_MARGIN",
    "MIN_PIXEL_DF",
    "PIXEL_MODES",
    "ROUNDING",
    "TRIPWIRE_ALPHA",
    "TRIPWIRE_RATIO",
    "PixelMoments",
    "PixelUse",
    "Tripwire",
    "global_limit",
    "local_limit",
    "moment_conflict",
    "pixel_eligibility",
    "pixel_paired",
    "pixel_use",
    "pixel_welch",
    "summed_means",
    "tripwire",
]

#: Below this Satterthwaite df (3) a tile-channel keeps the tile test: skewed pixels (measured: at 2 v 2 the
#: glass caustic's false `biased` rate fell from 21 to 6 in 1000 with it).
MIN_PIXEL_DF = 100.0

#: (4) holds while the smaller side has at most this many passes: a pixel's few passes agreeing by chance is a risk
#: of small counts (two-valued at even odds: 2 / 2^(2n) for both sides of n), and past them V_both would hold a
#: real bias's per-pixel differences, which grow against the noise with the passes (Filter Glossy moves light
#: between the pixels of a tile: at 512 passes a side (4) found nothing).
POOLED_UP_TO = 8

#: Elements (pixels x channels) of the band of rows `PixelMoments.add` updates at a time: its pass, mean, M2 and two
#: scratch arrays, about 1 MB, stay within a core's cache (bands of 2 to 8 rows of a 1920x1080 RGB pass took the
#: same time, 1 row more, the whole image at once 2x).
BAND_ELEMENTS = 1 << 15

#: "auto": where the runs' records prove the settings (`pixel_eligibility`); "on": the user vouches for the renderer
#: (an external one, or settings not measured), the tripwire still refuses; "off": the tile test everywhere.
PIXEL_MODES = ("auto", "on", "off")

#: (Blender release, sampling pattern) whose pixels were measured independent or negatively correlated within a
#: pass: D = Var(tile sum) / sum Var(pixel) within its permutation null or below it, on the diffuse corner and the
#: glass caustic (docs/findings/pixel_variance.md). AUTOMATIC renders BLUE_NOISE's passes in 4.5-5.3; 5.1, 5.2
#: and 5.3 render the same passes. 4.2-4.4 were not measured. Extend only by measurement.
INDEPENDENT_PATTERNS = frozenset(
    {("3.4", pattern) for pattern in ("SOBOL", "PROGRESSIVE_MULTI_JITTER")}
    | {
        (release, pattern)
        for release in ("4.5", "5.0", "5.1", "5.2", "5.3")
        for pattern in ("TABULATED_SOBOL", "BLUE_NOISE", "AUTOMATIC")
    }
)

#: The tripwire's level: the chance, under independent normal pixels, that one comparison's tripwire refuses by
#: its median over a few tiles (`global_limit`), or by some tile-channel of some size (`local_limit`, Bonferroni
#: over the tile-channels, before `LOCAL_MARGIN`).
TRIPWIRE_ALPHA = 1e-4
#: The factor on the local limit that covers what rendered independent pixels do beyond normal ones: heavy-tailed
#: tile sums (a dark, defocused tile of sparse hits: excess kurtosis 4.7 where chi² assumes 0) vary more than
#: chi²(n - 1) says. Measured on the cached pools of every built-in scene (`benchmarks.studies.local_tripwire`;
#: docs/findings/pixel_variance.md): 1.5 was passed once in 68 600 A/A trials, by that tile at D = 1.07, within
#: its permutation null.
LOCAL_MARGIN = 2.0

#: How far the identities (5) and (6) of `moment_conflict` may miss: this many times the rounding of the sums
#: involved, (tile x float32's epsilon + (passes + pixels of a tile) x float64's), x sqrt(passes + 1) x the tile's
#: scale, sum_p (|mean_p| + sqrt(M2_p)), which bounds every pass's sum of |pixel|. A float32 pass's tile sums add
#: its rows' partial sums of `tile` pixels in float32 (`tiles.tile_sums`); a Welford mean and M2 and the float64
#: sums round at most linearly in the values summed; 4 to spare. A damaged or foreign array misses by far more.
ROUNDING = 4.0

#: The tripwire's limit on the median over tile-channels of (tile-sum variance / V), each divided by the median
#: of its null distribution chi²(n - 1) / (n - 1): independent pixels give about 1, the scrambling distance 0.1
#: about 100 (`tripwire`); higher where few tiles make the median itself noisy (`global_limit`).
TRIPWIRE_RATIO = 3.0


class PixelMoments:
    """Each pixel's mean and M2 (sum of squared deviations) over a run's passes, float64, H×W×C.

    Updated pass by pass (Welford) and merged exactly (Chan et al.), so a resumed or merged run has the moments
    of all its passes at once; float64 keeps a bright pixel's variance where its mean is large.
    """

    def __init__(self, height: int, width: int, channels: int = 3):
        self.n = 0
        self.mean = np.zeros((height, width, channels))
        self.m2 = np.zeros((height, width, channels))
        self._memo: dict = {}  # what `terms` computed at this n (every scale asks again)
        self._conflicts: dict = {}  # what `conflict` found at this n, by the tile sums' grid and array
        self._merged: tuple | None = None  # (the other moments, their n, `merged` with them)

    @classmethod
    def of(
        cls, mean: npt.ArrayLike, m2: npt.ArrayLike, n: int, names: tuple[str, str] = ("`mean`", "`m2`")
    ) -> PixelMoments:
        """Moments read back (a statistics file) or computed elsewhere; checked: every mean finite, every M2
        finite and >= 0, or WelchInputError naming the array as `names` say (a file's arrays by their keys)."""
        mean, m2 = np.asarray(mean, dtype=np.float64), np.asarray(m2, dtype=np.float64)
        if mean.ndim != 3 or mean.shape != m2.shape:
            raise WelchInputError(f"pixel moments must be two H×W×C arrays, got {mean.shape} and {m2.shape}")
        # A finite sum has finite terms, and a NaN makes the minimum NaN: one pass over each array where all is
        # well (at 1920x1080 a file's check took 12 ms as masks), the masks only to name what is not.
        with np.errstate(invalid="ignore", over="ignore"):
            if not np.isfinite(mean.sum()):
                _check_values(names[0], mean, "finite", np.isfinite(mean))
            if mean.size and not (np.isfinite(m2.sum()) and m2.min() >= 0):
                _check_values(names[1], m2, "finite and >= 0", np.isfinite(m2) & (m2 >= 0))
        out = cls(*mean.shape)
        out.n, out.mean, out.m2 = int(n), mean, m2
        return out

    @classmethod
    def of_passes(cls, images: npt.ArrayLike, channels: int = 3) -> PixelMoments:
        """The moments of a stack of passes (n, H, W, C) at once: the oracle the streaming path must equal."""
        images = np.asarray(images, dtype=np.float64)[..., :channels]
        if len(images) == 0:
            return cls(*images.shape[1:])
        mean = images.mean(axis=0)
        return cls.of(mean, ((images - mean) ** 2).sum(axis=0), len(images))

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.mean.shape

    def add(self, image: np.ndarray) -> None:
        """Add one pass (H×W×C or more channels; the first C are used).

        Welford's update, a band of `BAND_ELEMENTS` at a time: the band's pass, mean, M2 and the two scratch
        arrays stay in a core's cache, so every array travels between memory and the core once a pass (the same
        operations on the whole arrays at once take twice as long at 1920x1080, measured), and the rows in one chunk
        a core (`welch_core.parallel`). Each pixel's result is the same, bit for bit, however the rows are banded
        or chunked."""
        x = np.asarray(image)[..., : self.shape[2]]
        if x.shape != self.shape:
            raise WelchInputError(f"`image` must be {self.shape[0]}x{self.shape[1]} like the moments, got {x.shape}")
        self._memo.clear()
        self._conflicts.clear()
        self._merged = None
        self.n += 1
        band = max(1, BAND_ELEMENTS // (self.shape[1] * self.shape[2]))
        parallel.by_rows(lambda rows: self._add_rows(x, rows, band), self.shape[0], band, x.size)

    def _add_rows(self, x: np.ndarray, rows: slice, band: int) -> None:
        """Welford's update of `rows`, `band` rows at a time."""
        n, factor = self.n, (self.n - 1) / self.n
        scratch = np.empty((2, band, *self.shape[1:]))  # a band's delta and step: 2 x 0.25 MB
        for start in range(rows.start, rows.stop, band):
            part = slice(start, min(start + band, rows.stop))
            mean, m2 = self.mean[part], self.m2[part]
            delta, step = scratch[0, : len(mean)], scratch[1, : len(mean)]
            np.subtract(x[part], mean, out=delta)
            np.multiply(delta, delta, out=step)  # Welford: M2 grows by delta² (n - 1) / n, the mean by delta / n
            step *= factor
            m2 += step
            delta /= n
            mean += delta

    def absorb(self, other: PixelMoments) -> None:
        """Add the passes of `other` (another run's moments, e.g. a worker's chunk) to these, in place: `merged`'s
        arithmetic, the same bits, a band of rows at a time on every core, with no image-sized temporaries."""
        if self.shape != other.shape:
            raise WelchInputError(f"pixel moments of different images: {self.shape} and {other.shape}")
        if not other.n:
            return
        self._memo.clear()
        self._conflicts.clear()
        self._merged = None
        n = self.n + other.n
        if not self.n:
            np.copyto(self.mean, other.mean)
            np.copyto(self.m2, other.m2)
            self.n = n
            return
        share, weight = other.n / n, self.n * other.n / n
        band = max(1, BAND_ELEMENTS // (self.shape[1] * self.shape[2]))

        def rows(part: slice) -> None:
            for start in range(part.start, part.stop, band):
                at = slice(start, min(start + band, part.stop))
                delta = other.mean[at] - self.mean[at]
                self.m2[at] += other.m2[at]
                self.m2[at] += delta * delta * weight
                self.mean[at] += delta * share

        parallel.by_rows(rows, self.shape[0], band, self.mean.size)
        self.n = n

    def merged(self, other: PixelMoments) -> PixelMoments:
        """The moments of both runs' passes together (neither changes)."""
        if self.shape != other.shape:
            raise WelchInputError(f"pixel moments of different images: {self.shape} and {other.shape}")
        n = self.n + other.n
        if not self.n or not other.n:
            source = self if self.n else other
            return PixelMoments.of(source.mean.copy(), source.m2.copy(), source.n)
        delta = other.mean - self.mean
        mean = self.mean + delta * (other.n / n)
        m2 = self.m2 + other.m2 + delta**2 * (self.n * other.n / n)
        return PixelMoments.of(mean, m2, n)

    def variance(self) -> np.ndarray:
        """Each pixel's unbiased sample variance (NaN where n < 2)."""
        if self.n < 2:
            return np.full(self.shape, np.nan)
        return self.m2 / (self.n - 1)

    def merged_with(self, other: PixelMoments) -> PixelMoments:
        """`merged`, kept while neither changes (every scale of a comparison asks for it)."""
        if self._merged is None or self._merged[0] is not other or self._merged[1] != other.n:
            self._merged = (other, other.n, self.merged(other))
        return self._merged[2]

    def terms(self, tile: int, grid: tuple[int, int], covered: tuple[int, int], about_zero: bool = False):
        """V = sum_p s_p² and Q = sum_p (s_p²)² per tile-channel of a `grid` of `tile`-pixel tiles over the
        `covered` pixels (the right and bottom tiles partial where the tile does not divide them; a coarse scale's
        one tile may be larger than the image), as in (1) and (3). `about_zero`: each pixel's second moment about 0
        over its n passes, sum x² / n, instead of s_p² (see (4)). A coarser tile's terms are the block sums of a
        finer one's already computed: the pixels are read once per comparison."""
        grid, covered = tuple(grid), tuple(covered)
        key = (tile, grid, covered, about_zero)
        if key in self._memo:
            return self._memo[key]
        finer = [k for k in self._memo if k[2:] == (covered, about_zero) and k[0] < tile and tile % k[0] == 0]
        if finer:
            base = max(finer)
            factor = tile // base[0]
            self._memo[key] = tuple(_block_sums(a, factor, grid) for a in self._memo[base])
            return self._memo[key]
        n = self.n

        def s2(m2, mean):  # each pixel's s_p² (or second moment about 0), a row of tiles at a time
            if about_zero:
                return m2 / n + mean**2
            return m2 / (n - 1) if n > 1 else np.full(m2.shape, np.nan)

        self._memo[key] = _tile_totals((self.m2, self.mean), tile, grid, covered, s2, also=np.square)  # V, Q
        return self._memo[key]

    def conflict(self, tile: int, grid: tuple[int, int], covered: tuple[int, int], sums: np.ndarray):
        """Per tile-channel of a `grid` of `tile`-pixel tiles over the `covered` pixels, whether these moments can
        be those of the passes whose tile sums are `sums` (n, rows, columns, channels), by (5) and (6) of
        `moment_conflict`: two boolean arrays (the means, the spread), True where they contradict them. Kept while
        the moments do not change (a file's are checked when it is read, and again before the pixel test)."""
        key = (tile, tuple(grid), tuple(covered), sums.__array_interface__["data"][0], sums.shape)
        if key in self._conflicts:
            return self._conflicts[key]
        with np.errstate(invalid="ignore", over="ignore"):
            total, size = _tile_totals(self.mean, tile, grid, covered, also=np.abs)
            spread = _tile_totals(self.m2, tile, grid, covered, np.sqrt)
            scale = size + spread
            n = len(sums)
            rounding = tile * np.finfo(np.float32).eps + (n + tile * tile) * np.finfo(np.float64).eps
            slack = ROUNDING * rounding * np.sqrt(n + 1.0) * scale
            finite = np.isfinite(sums).all(axis=0)
            mean_bad = ~finite | (np.abs(total - sums.mean(axis=0)) > slack)  # (5)
            varies = np.sqrt(((sums - sums.mean(axis=0)) ** 2).sum(axis=0))
            spread_bad = finite & ~mean_bad & (varies > spread + slack)  # (6)
        self._conflicts[key] = mean_bad, spread_bad
        return mean_bad, spread_bad


def summed_means(mean: np.ndarray, n: int) -> np.ndarray:
    """n x `mean` in float32, computed in float64: a run's per-pixel sum (for display) from its pixels' means."""
    total = np.empty(mean.shape, np.float32)
    np.multiply(mean, n, out=total, dtype=np.float64, casting="same_kind")
    return total


def _check_values(name: str, values: np.ndarray, allowed: str, good: np.ndarray) -> None:
    """WelchInputError naming `name`, what it must be and its first bad value with where it is, unless all `good`."""
    if good.all():
        return
    y, x, c = np.unravel_index(int(np.argmin(good)), good.shape)
    bad = int((~good).sum())
    where = f"pixel x {x}, y {y}, channel {c}" + (f", and {bad - 1} more" if bad > 1 else "")
    raise WelchInputError(f"{name} must be {allowed}, got {float(values[y, x, c])!r} ({where})")


def _tile_totals(values, tile: int, grid: tuple[int, int], covered: tuple[int, int], of=None, also=None):
    """Sums of `values` (H×W×C), or of `of(values)` (elementwise: np.sqrt; `values` may then be a tuple of such
    arrays, its arguments), over the `covered` pixels of each tile of a `grid` of `tile`-pixel tiles (the right and
    bottom tiles partial where the tile does not divide them), in float64; with `also` (elementwise: np.square),
    the sums of `also` of the same values too, from the same pass over the pixels (a pair). `of` is applied a row of
    tiles at a time: no image-sized array is made (a new one's first write is slow where the kernel compacts memory
    for it)."""
    arrays = values if isinstance(values, tuple) else (values,)
    outs = [np.zeros((grid[0], grid[1], arrays[0].shape[2])) for _ in range(1 if also is None else 2)]
    rows, cols = min(covered[0], grid[0] * tile), min(covered[1], grid[1] * tile)
    full = min(cols // tile, grid[1])  # complete tiles across; a partial one after them where the columns go on

    def tile_rows(chunk: slice) -> None:
        # A row of tiles at a time: its rows summed first with a contiguous inner axis, then its columns (4x faster
        # than one sum over both; no padded copy of the image).
        for row in range(chunk.start, chunk.stop):
            bands = [a[row * tile : min((row + 1) * tile, rows), :cols] for a in arrays]
            band = bands[0] if of is None else of(*bands)
            for out, summed in zip(outs, (band, also(band)) if also is not None else (band,), strict=True):
                summed = summed.sum(axis=0, dtype=np.float64)
                if full:
                    out[row, :full] = summed[: full * tile].reshape(full, tile, -1).sum(axis=1)
                if cols > full * tile:
                    out[row, full] = summed[full * tile :].sum(axis=0)

    # The rows of tiles in one chunk a core; each tile's sum is the same whichever chunk it is in.
    parallel.by_rows(tile_rows, -(-rows // tile), 1, rows * cols * arrays[0].shape[2])
    return outs[0] if also is None else tuple(outs)


def _block_sums(values: np.ndarray, factor: int, grid: tuple[int, int]) -> np.ndarray:
    """Sums of `factor` x `factor` blocks of a (rows, columns, channels) grid, the last blocks partial, as `grid`."""
    padded = np.zeros((grid[0] * factor, grid[1] * factor, values.shape[2]))
    rows, cols = min(values.shape[0], padded.shape[0]), min(values.shape[1], padded.shape[1])
    padded[:rows, :cols] = values[:rows, :cols]
    return padded.reshape(grid[0], factor, grid[1], factor, -1).sum(axis=(1, 3))


def _replace_variance(result: TTestResult, se2, df, pvalue_method) -> TTestResult:
    """`result` with the squared standard error `se2`, its df, and the t and p (by `pvalue_method`) that follow."""
    valid = result.reason == Reason.VALID
    with np.errstate(divide="ignore", invalid="ignore"):
        se = np.sqrt(se2)
        t = np.where(valid, -result.mean_difference / se, np.nan)
    df = np.where(valid, df, np.nan)
    p = np.full(t.shape, np.nan)
    p[valid] = two_sided_pvalue(t[valid], df[valid], pvalue_method)
    return dataclasses.replace(result, statistic=t, df=df, pvalue=p, standard_error=se)


def pixel_welch(ref, test, pvalue_method: str = "exact") -> TTestResult:
    """(2)-(4) per tile-channel of two runs (`TileStats` with `pixels`), as a `TTestResult`: the reasons of
    Welch's test on the tile sums (a constant tile has zero pixel variances too)."""
    v_ref, q_ref = ref.pixel_terms()
    v_test, q_test = test.pixel_terms()
    result = welch_from_stats(ref.mean, v_ref, ref.n, test.mean, v_test, test.n, pvalue_method=pvalue_method)
    with np.errstate(divide="ignore", invalid="ignore"):
        a, b = v_ref / ref.n, v_test / test.n
        df = (a + b) ** 2 / (q_ref / (ref.n**2 * (ref.n - 1.0)) + q_test / (test.n**2 * (test.n - 1.0)))
    if min(ref.n, test.n) > POOLED_UP_TO:
        return _replace_variance(result, a + b, df, pvalue_method)
    both = ref.pixels.merged_with(test.pixels)  # (4): each pixel's variance over both sides' passes
    v_both, q_both = both.terms(ref.tile, (ref.tiles_y, ref.tiles_x), ref.covered)
    with np.errstate(divide="ignore", invalid="ignore"):
        pooled = v_both * (1.0 / ref.n + 1.0 / test.n)
        pooled_df = (ref.n + test.n - 1.0) * v_both**2 / q_both
    larger = pooled > a + b
    return _replace_variance(result, np.where(larger, pooled, a + b), np.where(larger, pooled_df, df), pvalue_method)


def pixel_paired(differences, pvalue_method: str = "exact") -> TTestResult:
    """The paired form of (2)-(4) per tile-channel, on the per-seed differences test - reference (a `TileStats`
    whose `pixels` are the moments of each pixel's difference): t = mean / sqrt(V / n) with df = (n - 1) V² / Q,
    V and Q of the differences' pixel variances, or of their second moments about 0 (n df) where larger."""
    v, q = differences.pixel_terms()
    n = differences.n
    result = paired_from_stats(differences.mean, v, n, pvalue_method=pvalue_method)
    if n > POOLED_UP_TO:
        with np.errstate(divide="ignore", invalid="ignore"):
            return _replace_variance(result, v / n, (n - 1.0) * v**2 / q, pvalue_method)
    v0, q0 = differences.pixels.terms(differences.tile, differences.grid_shape[:2], differences.covered, True)
    with np.errstate(divide="ignore", invalid="ignore"):
        larger = v0 > v
        se2 = np.where(larger, v0, v) / n
        df = np.where(larger, n * v0**2 / q0, (n - 1.0) * v**2 / q)
    return _replace_variance(result, se2, df, pvalue_method)


def moment_conflict(run) -> tuple[str, str] | None:
    """Whether the pixel moments of `run` (a `TileStats` whose `pixels` are kept) contradict its tile sums: (the
    array, one line saying how) or None. Moments of the same passes as the tile sums satisfy, per tile-channel,

        sum_p mean_p = the mean of the tile sums over the passes                                        (5)
        sqrt(M2 of the tile sums) <= sum_p sqrt(M2_p)                                                   (6)

    up to rounding (`ROUNDING`): (5) because a tile sum is the sum of its pixels; (6) because the tile
    sums' M2 is the sum of the pixels' co-moments, each at most sqrt(M2_p M2_q) (Cauchy-Schwarz), so tile sums
    that vary need pixels that vary. Nothing else about the spread is certain (pixels may correlate either way):
    the `tripwire` judges the rest. A tile-channel with non-finite tile sums contradicts (5): a pass with NaN or inf
    pixels leaves a run without moments."""
    if run.pixels is None or run.n == 0:
        return None
    mean_bad, spread_bad = run.pixels.conflict(run.tile, (run.tiles_y, run.tiles_x), run.covered, run.sums)
    total = mean_bad.size
    if mean_bad.any():
        return "pixel_mean", (f"in {int(mean_bad.sum())} of {total} tile-channels the pixels' means do not add up to "
                              "the mean tile sum")  # fmt: skip
    if spread_bad.any():
        return "pixel_m2", (f"in {int(spread_bad.sum())} of {total} tile-channels the tile sums vary more than "
                            "their pixels can")  # fmt: skip
    return None


@dataclass(frozen=True)
class Tripwire:
    """What the `tripwire` measured: the median ratio of the tile sums' variance to V over every tile-channel
    (`ratio`) and its limit, the largest tile-channel's ratio against its local limit (`local`: above 1 refuses)
    with the ratio itself, the limit and where it is, and the tile-channels whose tile sums vary while V is 0 (or
    NaN), which moments of their passes can't give (`moment_conflict`)."""

    ratio: float  # the median over tile-channels of s²(tile sums) / V over that of chi²(n - 1) / (n - 1); NaN: none
    contradicted: int = 0
    local: float = float("nan")  # the largest s²(tile sums) / V over its limit, of any tile-channel of any size
    local_ratio: float = float("nan")  # that tile-channel's s²(tile sums) / V
    local_limit: float = float("nan")  # and its limit (`local_limit`)
    where: str = ""  # that tile-channel, in words
    ratio_limit: float = TRIPWIRE_RATIO  # `global_limit`

    def refusal(self) -> str | None:
        """Why the pixel test is refused, in one line, or None."""
        if self.contradicted:
            return (f"refused: in {self.contradicted} tile-channels the tile sums vary while their pixels do not "
                    "(pixel moments that contradict the passes)")  # fmt: skip
        if self.ratio > self.ratio_limit:
            return (f"refused: the tile sums vary {self.ratio:.3g}x more than their pixels say (pixels correlated "
                    "within a pass)")  # fmt: skip
        if self.local > 1:
            return (f"refused: the tile sums of {self.where} vary {self.local_ratio:.3g}x more than their pixels say, "
                    f"past the {self.local_limit:.3g}x independent pixels reach (pixels correlated within a pass "
                    "there)")  # fmt: skip
        return None


def global_limit(n: int, tiles: int) -> float:
    """The largest median ratio (`Tripwire.ratio`) the tripwire allows over `tiles` tiles of runs of `n` passes:
    `TRIPWIRE_RATIO`, or where the tiles are few, the upper `TRIPWIRE_ALPHA` point of the median of `tiles` values
    of chi²(n - 1) over its median, which independent normal pixels pass with that chance (a tile's channels share
    its noise: counted once). At 2 passes a side of a 32x32 image in 16-px tiles (8 tiles) it is 9.7: the median
    of so few passed 3 in 9 of 100 A/A trials of the diffuse corner."""
    from scipy import special  # not scipy.stats: its import alone (0.5 s) is most of `compare`'s time budget

    k, df = (tiles + 1) // 2, n - 1  # the median passes x where k of the tiles do (numpy's median: at most the kth)
    # The chance q a tile passes x at which k or more of the tiles do with chance TRIPWIRE_ALPHA: P(Binomial(tiles,
    # q) >= k) = I_q(k, tiles - k + 1), the regularized incomplete beta function, solved for q.
    p = special.betaincinv(k, tiles - k + 1, TRIPWIRE_ALPHA)
    return max(TRIPWIRE_RATIO, float(_chi2_isf(p, df) / _chi2_median(df)))


def local_limit(n: int, count: int) -> float:
    """The largest s²(tile sums) / V one of `count` tile-channels of a run of `n` passes is allowed (the local
    tripwire): `LOCAL_MARGIN` x the upper `TRIPWIRE_ALPHA` / `count` point of chi²(n - 1) / (n - 1), what one
    tile-channel of independent normal pixels exceeds with that chance (V taken as exact: with the pixels' many
    degrees of freedom it nearly is; where a few pixels carry it, s² and V rise together and the ratio nears 1)."""
    return LOCAL_MARGIN * float(_chi2_isf(TRIPWIRE_ALPHA / max(count, 1), n - 1)) / (n - 1)


def _chi2_isf(p: float, df: float) -> float:
    """The upper `p` point of chi²(`df`) (what scipy.stats.chi2.isf computes, by the same function)."""
    from scipy import special

    return float(special.chdtri(df, p))


def _chi2_median(df: float) -> float:
    """The median of chi²(`df`) (scipy.stats.chi2.median's value, by the same function)."""
    from scipy import special

    return float(2 * special.gammaincinv(df / 2, 0.5))


def tripwire(*runs) -> Tripwire:
    """How much more the tile sums vary than their pixels say, pooled over `runs` (both sides, or a paired run's
    differences), as a whole and locally:

    * the median over valid tile-channels of s²(tile sums) / V, divided by the median of chi²(n - 1) / (n - 1)
      (what independent normal pixels give): about 1 where (1) holds, below where pixels are negatively
      correlated; gross positive correlation everywhere (the scrambling distance 0.1: about 100) shows at 2 passes
      a side; above `global_limit` (3, more over a few tiles) refuses;
    * each tile-channel of every tile size (the stored tile, 2x, 4x, ... up to the whole image, as the comparison
      tests them) on its own: s²(tile sums) / V above `local_limit` refuses, which catches pixels that share their
      noise in one region only (a median over the image does not move for one tile in four);
    * a tile-channel whose tile sums vary while its V is 0 or NaN is no ratio but a contradiction (tile sums of
      pixels that never vary can't vary): it is counted, and refuses.

    Cheap: the coarser tiles' V are block sums of the finer ones' (`PixelMoments.terms`, kept for the comparison
    that follows) and their tile sums block sums of the stored ones."""
    ratios, contradicted, local, tiles = [], 0, [], 0
    for run in runs:
        if run.n < 2:
            continue
        factor = 1
        while True:
            coarse = run if factor == 1 else run.retile(factor)
            v, _ = coarse.pixel_terms()
            with np.errstate(divide="ignore", invalid="ignore"):
                r = coarse.variance / v
            valid = np.isfinite(r) & (v > 0)
            if factor == 1:  # a coarser tile contradicts only where a stored one does
                contradicted += int(((coarse.variance > 0) & ~(v > 0)).sum())
                tiles += int(valid.any(axis=-1).sum())
                if valid.any():
                    ratios.append(r[valid] / (_chi2_median(run.n - 1) / (run.n - 1)))
            if valid.any():
                local.append((run.n, coarse.tile, int(valid.sum()), np.where(valid, r, -np.inf)))
            if max(run.tiles_y, run.tiles_x) <= factor:
                break
            factor *= 2
    if not local:
        return Tripwire(float("nan"), contradicted)
    ratio = float(np.median(np.concatenate(ratios))) if ratios else float("nan")
    ratio_limit = global_limit(min(entry[0] for entry in local), tiles)
    count = sum(entry[2] for entry in local)
    worst = (-np.inf, 0.0, 0.0, "")
    for n, tile, _, r in local:
        limit = local_limit(n, count)
        index = np.unravel_index(int(np.argmax(r)), r.shape)
        if r[index] / limit > worst[0]:
            row, col, channel = (int(i) for i in index)
            where = f"the {tile}x{tile} tile at x {col * tile}, y {row * tile}, channel {channel}"
            worst = (float(r[index] / limit), float(r[index]), limit, where)
    return Tripwire(ratio, contradicted, *worst, ratio_limit=ratio_limit)


@dataclass(frozen=True)
class PixelUse:
    """Whether a comparison tested tiles by their pixel variances, and why (or why not), for the report."""

    mode: str  # one of PIXEL_MODES
    used: bool
    reason: str  # one line: what allowed it, or what stopped it
    share: float = 0.0  # of the valid tile-channels of every scale that the pixel test decided
    ratio: float = float("nan")  # the tripwire's measure

    def to_json(self) -> dict:
        return {"mode": self.mode, "used": self.used, "reason": self.reason, "share": self.share,
                "tripwire": None if not np.isfinite(self.ratio) else self.ratio, "min_df": MIN_PIXEL_DF}  # fmt: skip


def pixel_eligibility(info) -> str | None:
    """Why a run's record does not prove independent pixels (one line), or None where it does: Cycles passes
    rendered by this tool (a built-in scene or a .blend it hashed, not `ingest` or `--command`), of a (release,
    sampling pattern) in `INDEPENDENT_PATTERNS`, scrambling distance 1 and the automatic one off (it changes
    nothing at 1 spp), no denoiser, no adaptive sampling."""
    if info.renderer != "Cycles" or not info.scene_id.startswith(("builtin:", "sha256:")):
        return "not Cycles passes rendered by this tool (vouch for the renderer with --pixel-variance on)"
    release = ".".join(info.renderer_version.split(".")[:2])
    if (release, info.sampling_pattern) not in INDEPENDENT_PATTERNS:
        return f"the sampling pattern {info.sampling_pattern} of Blender {release} is not measured independent"
    settings = info.settings
    distance = settings.get("cycles.scrambling_distance")
    if distance != 1.0:
        return f"cycles.scrambling_distance is {distance} (pixels share samples below 1)"
    if settings.get("cycles.auto_scrambling_distance") and info.spp > 1:
        return "cycles.auto_scrambling_distance is on (pixels share samples)"
    switches = [k for k in settings if k.endswith("cycles.use_denoising")] + ["cycles.use_adaptive_sampling"]
    for name in switches:
        if settings.get(name, True):
            return f"{name} is on"
    return None


def pixel_use(ref, test, method, mode: str, differences=None) -> PixelUse:
    """Whether `ref` and `test` (`TileStats`) are tested by their pixel variances under `mode` (see
    `PIXEL_MODES`) and their tile test `method` (`welch_core.tile_test.TileTestMethod`), and why: the runs must
    keep pixel moments (a paired run: the moments of each pixel's difference per seed, `differences`, a
    `TileStats` of the per-seed differences that keeps them, `TileTestMethod.differences`), have two
    passes a side, be eligible by their records (`pixel_eligibility`, unless the user vouches with "on"), keep
    moments that can be those of their passes (`moment_conflict`), and pass the `tripwire`."""
    if mode not in PIXEL_MODES:
        raise WelchInputError(f"`pixel_variance` must be one of {PIXEL_MODES}, got {mode!r}")
    if mode == "off":
        return PixelUse(mode, False, "off (--pixel-variance off)")
    runs = method.pixel_runs(ref, test, differences)
    if isinstance(runs, str):
        return PixelUse(mode, False, runs)
    if ref.pixels is None or test.pixels is None:
        why = "a run keeps no pixel moments (made before they were kept, or it kept a pass with non-finite pixels)"
        return PixelUse(mode, False, why)
    if min(ref.n, test.n) < 2:
        return PixelUse(mode, False, "fewer than 2 passes a side")
    if mode == "auto":
        for side, run in (("reference", ref), ("test", test)):
            reason = pixel_eligibility(run.info)
            if reason is not None:
                return PixelUse(mode, False, f"the {side}: {reason}")
    for side, run in (("reference", ref), ("test", test)):
        conflict = moment_conflict(run)
        if conflict is not None:
            return PixelUse(mode, False, f"refused: the {side}'s pixel moments contradict its tile sums: {conflict[1]}")
    measured = tripwire(*runs)
    refusal = measured.refusal()
    if refusal is not None:
        return PixelUse(mode, False, refusal, ratio=measured.ratio)
    why = "vouched for (--pixel-variance on)" if mode == "on" else "Cycles passes with independent pixels"
    return PixelUse(mode, True, why, ratio=measured.ratio)
