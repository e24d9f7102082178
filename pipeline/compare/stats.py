"""The noise-aware test of one frame against its reference (docs/compare.md).

Two path-traced frames of the same picture differ by noise whenever the seed, the variant,
the thread count or the machine differs. The question per region is whether the difference
NEW - REF is explained by that noise. Everything is estimated from the two images:

- D = NEW - REF, per channel (R, G, B, A).
- Per-pixel noise variance of D from Immerkaer's mask M = [1 -2 1]^T [1 -2 1] applied to D
  (v = (M * D)^2 / 36, exact for independent noise; Immerkaer 1996). M is the product of a
  second difference in x and one in y, so it is blind to anything constant, linear or
  varying along one axis only: a region made uniformly brighter leaves no trace in v.
- Block sums over windows of k x k blocks of `block` pixels, k = 1, 2, 4, ... and the whole
  frame: z = sum(D) / sqrt(kappa * sum(v)). kappa corrects for neighbouring pixels' noise
  being correlated (the reconstruction filter splats a sample over several pixels): it is
  the ratio of the variance of a window's sum to sum(v). For motion's frames it is a
  property of the filter the header names (FILTER_KAPPA, measured once by the bench); for
  other frames it is measured on the frame from differences of adjacent blocks (a change
  confined to some blocks, or one that shifts them all alike, cancels in those
  differences; the median ignores the rest), which is noisier.
- A window is different when |z| exceeds a threshold set by the number of tests (a
  Bonferroni bound at `alpha` false alarms per frame, never below `z_min`); the measured
  false-alarm rate over many seeds is in bench/bench_compare.py.

A window takes the larger of its own variance and that of the window one block wider on
every side, scaled to its area (a few blocks' own estimate has too few degrees of freedom
for the far tail the threshold lives in). A firefly (one huge sample) raises sum(v) as much as sum(D):
its z stays near 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

Verdict = Literal["identical", "equal", "different"]
CHANNELS = ("R", "G", "B", "A")

ALPHA = 1e-4  # the nominal false-alarm probability per frame (Bonferroni over its tests)
Z_MIN = 6.0  # never a threshold below this (heavy-tailed path-tracing noise)
# (M * D)^2 / 36 is D's variance for independent noise: sum of M's squared weights = 6 * 6
_IMMERKAER = 36.0
_MEDIAN_CHI2_1 = 0.454936423119572  # the median of a chi-square with one degree of freedom
KAPPA_RANGE = (1.0, 1.0e4)
# kappa of motion's own frames by reconstruction filter (render.filter): the variance of a
# window's sum of D over the sum of its v, measured over 40 seed pairs of a still set at 4
# and 64 spp, 4- to 16-pixel windows (bench/bench_compare.py --part kappa; box 0.85-1.04,
# tent 2.8-5.1, gaussian 6.0-10.9), taken at the top of each range: a sample splatted over
# neighbouring pixels makes their noise alike, which the mask does not see
FILTER_KAPPA = {"box": 1.1, "tent": 5.0, "gaussian": 10.0}


@dataclass(frozen=True)
class Region:
    """A connected area of blocks that differ: its pixel box (x0, y0 inclusive, x1, y1
    exclusive), covered pixels, fraction of the frame, the channel that differs most, its
    peak z, the mean difference NEW - REF there (in that channel) and that relative to REF."""

    x0: int
    y0: int
    x1: int
    y1: int
    pixels: int
    fraction: float
    channel: str
    z: float
    mean_diff: float
    relative: float
    nonfinite: int = 0  # pixels whose value is NaN or infinite in one frame and not the same in the other

    def describe(self) -> str:
        """One phrase: where, how large, which channel, how much."""
        if self.nonfinite:
            return (f"x {self.x0}-{self.x1 - 1}, y {self.y0}-{self.y1 - 1} ({self.fraction * 100:.1f}% of the frame): "
                    f"{self.nonfinite} pixel(s) NaN or infinite in {self.channel}")
        sign = "brighter" if self.mean_diff > 0 else "darker"
        rel = f"{abs(self.relative) * 100:.1f}% {sign}" if math.isfinite(self.relative) else f"{self.mean_diff:+.3g}"
        return (f"x {self.x0}-{self.x1 - 1}, y {self.y0}-{self.y1 - 1} ({self.fraction * 100:.1f}% of the frame): "
                f"{self.channel} {rel} (z {self.z:+.1f})")


@dataclass
class FrameTest:
    """The test's outcome for one frame: verdict, the largest |z| and the threshold it was
    held to, the regions that differ (largest |z| first), kappa, per-channel RMS and
    largest absolute difference, and the per-block map of |z| (for the report)."""

    verdict: Verdict
    max_z: float = 0.0
    threshold: float = Z_MIN
    regions: list[Region] = field(default_factory=list)
    kappa: float = 1.0
    rms: dict[str, float] = field(default_factory=dict)
    max_abs: dict[str, float] = field(default_factory=dict)
    block: int = 8
    z_blocks: np.ndarray | None = None  # [gy, gx] largest |z| of a single-block window


def block_size(height: int, width: int) -> int:
    """Pixels per block side: 8, or 4 for frames under 64 pixels on their short side."""
    return 8 if min(height, width) >= 64 else 4


def _second_difference(a: np.ndarray, axis: int) -> np.ndarray:
    """a[i-1] - 2 a[i] + a[i+1] along `axis`, the edges reflected (a[-1] = a[1])."""
    x = np.moveaxis(a, axis, 0)
    out = np.zeros_like(x)
    if x.shape[0] > 2:
        np.subtract(x[:-2] + x[2:], 2.0 * x[1:-1], out=out[1:-1])
    if x.shape[0] > 1:
        out[0] = 2.0 * (x[1] - x[0])
        out[-1] = 2.0 * (x[-2] - x[-1])
    return np.moveaxis(out, 0, axis)


def _immerkaer(d: np.ndarray) -> np.ndarray:
    """(M * d)^2 / 36 per pixel and channel, d [H, W, C], edges reflected."""
    m = _second_difference(_second_difference(d, 1), 0)
    m *= m
    m *= 1.0 / _IMMERKAER
    return m


def _block_sums(x: np.ndarray, b: int) -> np.ndarray:
    """[H, W, C] -> [gy, gx, C] float64 sums over b x b blocks (the frame padded with zeros)."""
    h, w, c = x.shape
    gy, gx = -(-h // b), -(-w // b)
    if (h, w) != (gy * b, gx * b):
        padded = np.zeros((gy * b, gx * b, c), x.dtype)
        padded[:h, :w] = x
        x = padded
    rows = x.reshape(gy, b, gx * b, c).sum(axis=1, dtype=np.float64)  # [gy, W, C]
    return rows.reshape(gy, gx, b, c).sum(axis=2)


def _window_sums(g: np.ndarray, k: int) -> np.ndarray:
    """[gy, gx, C] -> [gy-k+1, gx-k+1, C] sums over every k x k window (summed-area table)."""
    s = np.zeros((g.shape[0] + 1, g.shape[1] + 1, g.shape[2]))
    s[1:, 1:] = g.cumsum(0).cumsum(1)
    return s[k:, k:] - s[:-k, k:] - s[k:, :-k] + s[:-k, :-k]


def _kappa(sd: np.ndarray, sv: np.ndarray, noisy: np.ndarray) -> float:
    """Variance of a block sum over the sum of its v, from adjacent full blocks' differences
    (colour channels pooled): median((S1 - S2)^2 / (V1 + V2)) / median(chi2_1), over the
    pairs of `noisy` blocks (a constant sky has no noise to measure)."""
    ratios = []
    pairs = ((np.s_[:, :-1], np.s_[:, 1:]), (np.s_[:-1], np.s_[1:]))  # left/right, top/bottom
    for first, second in pairs:
        var = sv[first] + sv[second]
        ok = noisy[first] & noisy[second]
        ok[..., 3:] = False  # alpha is often noise-free: the colour channels say it
        ratios.append(((sd[first] - sd[second]) ** 2 / np.where(ok, var, 1.0))[ok])
    r = np.concatenate(ratios)
    if r.size < 8:
        return KAPPA_RANGE[0] * 2.0  # too few blocks to measure: a cautious guess
    return float(np.clip(np.median(r) / _MEDIAN_CHI2_1, *KAPPA_RANGE))


def _as_z(t: np.ndarray, dof: np.ndarray) -> np.ndarray:
    """A t-value whose variance came from `dof` differing pixels -> the normal deviate of the
    same tail probability (Student's t). A block that an edge only nicks has its noise in a
    handful of pixels: its |t| of 6.7 is then as likely as a normal |z| of 3."""
    from scipy.special import ndtri, stdtr

    t = np.asarray(t, dtype=np.float64)
    dof = np.maximum(np.asarray(dof, dtype=np.float64) - 1.0, 1.0)
    # beyond 400 degrees of freedom t and z differ by under 1% where it matters; under
    # |t| = 2 the deviate is never near a threshold (and never above |t|): left as it is
    small = (dof < 400.0) & (np.abs(t) > 2.0)
    out = t.copy()
    if np.any(small):
        ts = np.abs(t[small])
        # the tail of t, then the normal deviate of that tail (stable far out: log-free enough for |z| < 37)
        tail = stdtr(dof[small], -ts)
        out[small] = np.sign(t[small]) * np.where(tail > 0, -ndtri(np.maximum(tail, 1e-300)), ts)
    return out


def threshold(tests: int, alpha: float = ALPHA, z_min: float = Z_MIN) -> float:
    """|z| above which a window differs: two-sided Bonferroni at `alpha` over `tests`."""
    from scipy.special import ndtri

    return max(z_min, float(-ndtri(alpha / (2.0 * max(tests, 1)))))


def compare_frame(new: np.ndarray, ref: np.ndarray, *, alpha: float = ALPHA, z_min: float = Z_MIN, block: int | None = None, kappa: float | None = None) -> FrameTest:
    """Compare NEW with REF ([H, W, C] linear, C <= 4, the same shape): identical, equal
    within noise or different, with the regions that differ. `kappa`: the noise's
    correlation factor when known (FILTER_KAPPA by the frames' filter), else measured."""
    if new.shape != ref.shape:
        raise ValueError(f"shapes differ: {new.shape} and {ref.shape}")
    if not (np.isfinite(new).all() and np.isfinite(ref).all()):
        return _with_nonfinite(new, ref, alpha=alpha, z_min=z_min, block=block, kappa=kappa)
    h, w, c = new.shape
    names = CHANNELS[:c]
    if np.array_equal(new, ref):
        zero = {n: 0.0 for n in names}
        return FrameTest("identical", rms=zero, max_abs=dict(zero), block=block or block_size(h, w))
    b = block or block_size(h, w)
    d = np.subtract(new, ref, dtype=np.float32)
    rms = {n: float(np.sqrt(np.mean(np.square(d[..., i], dtype=np.float64)))) for i, n in enumerate(names)}
    max_abs = {n: float(np.abs(d[..., i]).max()) for i, n in enumerate(names)}
    # only the channels that differ somewhere are tested (alpha is often 1 in both)
    active = [i for i in range(c) if rms[names[i]] > 0]
    if not active:  # every value equal (+0.0 and -0.0)
        return FrameTest("identical", rms=rms, max_abs=max_abs, block=b)
    names = tuple(names[i] for i in active)
    d = np.ascontiguousarray(d[..., active])
    sd = _block_sums(d, b)
    sv = _block_sums(_immerkaer(d), b)
    sr = _block_sums(np.abs(np.ascontiguousarray(ref[..., active], dtype=np.float32)), b)
    # half floats round to 11 bits: a floor under v for frames that differ only by rounding
    # (both frames' rounding, 2^-11 of a block's mean level per pixel)
    sv += 2.0 * (2.0 ** -11 * sr) ** 2 / (b * b)
    if kappa is None:
        # blocks whose every pixel was drawn and most of whose pixels differ: noise to measure
        noisy = _block_sums((d != 0).astype(np.float32), b) > 0.75 * b * b
        noisy[h // b :] = False
        noisy[:, w // b :] = False
        kappa = _kappa(sd, sv, noisy)
    kappa = float(kappa)

    # pixels that differ at all: a variance made of a few of them has few degrees of freedom
    sn = _block_sums((d != 0).astype(np.float32), b)
    scales = _window_scales(sd, sv, sn, kappa)
    tests = sum(z.size for _, z in scales)
    z_crit = threshold(tests, alpha, z_min)
    max_z = max(float(np.nanmax(np.abs(z))) for _, z in scales)
    marked, peak, peak_ch = _mark(scales, z_crit, sd, sv, sn, kappa)
    regions = _regions(marked, peak, peak_ch, sd, sr, b, h, w, names)
    return FrameTest("different" if regions else "equal", max_z, z_crit, regions, kappa, rms, max_abs, b, np.abs(scales[0][1]).max(axis=2))


def _with_nonfinite(new: np.ndarray, ref: np.ndarray, **test: object) -> FrameTest:
    """The test of frames holding NaN or infinite values: a pixel whose non-finite value is
    not the same in both frames is a difference (one region boxing them all), the rest is
    tested as usual with those values set to 0."""
    fin_new, fin_ref = np.isfinite(new), np.isfinite(ref)
    same = (new == ref) | (np.isnan(new) & np.isnan(ref))
    bad = ~(fin_new & fin_ref) & ~same  # [H, W, C]
    result = compare_frame(np.where(fin_new, new, 0.0).astype(new.dtype), np.where(fin_ref, ref, 0.0).astype(ref.dtype), **test)  # type: ignore[arg-type]
    pixels = bad.any(axis=2)
    if not pixels.any():
        return result
    h, w, c = new.shape
    ys, xs = np.nonzero(pixels)
    count = int(pixels.sum())
    channel = CHANNELS[int(np.nonzero(bad.any(axis=(0, 1)))[0][0])]
    where = "new" if (~fin_new & ~same).any() else "reference"
    region = Region(int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1, count, count / float(h * w),
                    f"{channel} of the {where} frame", math.inf, math.nan, math.nan, nonfinite=count)
    result.verdict = "different"
    result.regions = [region] + result.regions
    for i, n in enumerate(CHANNELS[:c]):
        if bad[..., i].any():
            result.max_abs[n] = math.inf
    return result


def _window_scales(sd: np.ndarray, sv: np.ndarray, sn: np.ndarray, kappa: float) -> list[tuple[int, np.ndarray]]:
    """(k, z [gy', gx', C]) for square windows of k = 1, 2, 4, ... blocks (up to half the
    grid), then (0, z [1, 1, C]) for the whole frame: the summed difference over its noise,
    as a normal deviate. sd, sv, sn: per-block sums of the difference, its variance
    estimate and the count of pixels that differ."""
    gy, gx = sd.shape[:2]
    scales: list[tuple[int, np.ndarray]] = []
    padded = np.pad(sv, ((1, 1), (1, 1), (0, 0)), mode="edge")
    padded_n = np.pad(sn, ((1, 1), (1, 1), (0, 0)), mode="edge")
    k = 1
    while k == 1 or (k <= max(gy, gx) // 2 and k <= min(gy, gx)):
        # the window's own variance, or its ring-widened neighbourhood's scaled to its area
        own = _window_sums(sv, k)
        ring = _window_sums(padded, k + 2) * (k * k / (k + 2) ** 2)
        dof = np.where(own >= ring, _window_sums(sn, k), _window_sums(padded_n, k + 2))
        t = _window_sums(sd, k) / np.sqrt(kappa * np.maximum(own, ring))
        scales.append((k, _as_z(t, dof)))
        k *= 2
    whole = sd.sum(axis=(0, 1)) / np.sqrt(kappa * sv.sum(axis=(0, 1)))
    scales.append((0, _as_z(whole, sn.sum(axis=(0, 1)))[None, None, :]))
    return scales


def _mark(scales: list[tuple[int, np.ndarray]], z_crit: float, sd: np.ndarray, sv: np.ndarray, sn: np.ndarray, kappa: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The blocks that differ [gy, gx], with the deviate and channel that marked each.

    Blocks marked by the smallest windows that differ; a larger window marks the blocks no
    smaller one did when those still differ on their own (a local change also tips the
    whole-frame sum, and must not make the whole frame its region)."""
    gy, gx = sd.shape[:2]
    marked = np.zeros((gy, gx), bool)
    peak = np.zeros((gy, gx))
    peak_ch = np.zeros((gy, gx), int)
    for k, z in scales:
        hit = np.abs(z).max(axis=2) > z_crit
        if not hit.any():
            continue
        for y, x in zip(*np.nonzero(hit)):
            ys, xs = (slice(0, gy), slice(0, gx)) if k == 0 else (slice(y, y + k), slice(x, x + k))
            free = ~marked[ys, xs]
            if not free.any():
                continue
            zw = z[y, x]
            if not free.all():
                # what smaller windows marked is theirs: does the rest of this one still differ?
                zw = _as_z(sd[ys, xs][free].sum(axis=0) / np.sqrt(kappa * sv[ys, xs][free].sum(axis=0)), sn[ys, xs][free].sum(axis=0))
                if not np.abs(zw).max() > z_crit:
                    continue
            ch = int(np.abs(zw).argmax())
            sub = np.zeros((gy, gx), bool)
            sub[ys, xs] = free
            marked |= sub
            peak[sub] = zw[ch]
            peak_ch[sub] = ch
    return marked, peak, peak_ch


def _regions(marked: np.ndarray, peak: np.ndarray, peak_ch: np.ndarray, sd: np.ndarray, sr: np.ndarray, b: int, h: int, w: int, names: tuple[str, ...]) -> list[Region]:
    """Connected (8-neighbour) areas of marked blocks, largest |z| first."""
    if not marked.any():
        return []
    from scipy.ndimage import label

    labels, count = label(marked, structure=np.ones((3, 3), int))
    out = []
    for i in range(1, count + 1):
        ys, xs = np.nonzero(labels == i)
        at = int(np.abs(peak[ys, xs]).argmax())
        ch = int(peak_ch[ys[at], xs[at]])
        x0, y0 = int(xs.min()) * b, int(ys.min()) * b
        x1, y1 = min(w, (int(xs.max()) + 1) * b), min(h, (int(ys.max()) + 1) * b)
        pixels = sum(min(b, h - y * b) * min(b, w - x * b) for y, x in zip(ys, xs))
        diff = float(sd[ys, xs, ch].sum())
        base = float(sr[ys, xs, ch].sum())
        out.append(Region(x0, y0, x1, y1, int(pixels), pixels / float(h * w), names[ch], float(peak[ys[at], xs[at]]),
                          diff / pixels, diff / base if base > 0 else float("inf")))
    out.sort(key=lambda r: -abs(r.z))
    return out
