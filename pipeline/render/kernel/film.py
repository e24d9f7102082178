"""The deterministic film of the `motion_path` integrator: an image whose bits do not
depend on the thread count.

Mitsuba's film splats every sample into its neighbours with atomic adds, whose order
varies with the threads; sums of floats then differ in the last bit. Here a pixel's
samples are consecutive lanes, so for each reconstruction-filter offset a row gather
(`row_sums`) adds one pixel's weighted samples in a fixed order, and the image gathers
those sums offset by offset, also in a fixed order: no atomics anywhere. Large sample
counts run as passes (at most $MOTION_MAX_LANES lanes each), summed in pass order; a
frame of more pixels than that runs in bands of rows (`bands`), each rendering the
filter's reach of rows beyond the rows it delivers, with a seed of its own.

Field rendering (`motion render --fields`) passes a field's `rows` (offset, step 2): the
film then traces and returns only that field's rows.
"""

from __future__ import annotations

import math
from typing import Any, Callable

import drjit as dr
import mitsuba as mi
import numpy as np

from ...errors import SampleCountError
from ...limits import env_size

# At most $MOTION_MAX_LANES (default 2^23, limits.ENV_SIZES) sample lanes are in flight
# per pass: per-sample colour, film position and filter weights are kept for the film,
# about 80 bytes a lane (~0.7 GB a pass). A 1080p frame at 256 spp is 531M lanes: it runs
# as passes of fewer samples per pixel. A lower value: less memory per worker, more passes.

# sample(scene, sampler, ray, medium, active) -> (radiance, valid, AOV channels)
SampleFn = Callable[..., tuple[Any, Any, list[Any]]]


def render(sample: SampleFn, scene: mi.Scene, sensor: Any, seed: Any, spp: int, rows: tuple[int, int] = (0, 1)) -> Any:
    """Render `sensor`'s image of `scene`, every sample's value from `sample` (the
    integrator's path). Returns a mi.TensorXf [H, W, 4 + AOV channels] (RGBA, alpha = the
    pixel's coverage); `rows` (offset, step): only rows offset, offset + step, ... (a
    field: step 2), H counting only those. A frame of more pixels than the lane budget
    ($MOTION_MAX_LANES) renders in bands of rows (`bands`), each a window with the filter's
    reach of rows above and below, so no pass holds more lanes than the budget."""
    film = sensor.film()
    sampler = sensor.sampler()
    spp = int(spp) if spp else int(sampler.sample_count())
    if spp < 1:
        raise SampleCountError(f"the film needs at least 1 sample per pixel, got {spp}")
    size = film.crop_size()
    width, height = int(size[0]), int(size[1])
    offset, step = rows
    out_h = (height - offset + step - 1) // step
    n_px = width * out_h
    apron = _reach(film.rfilter()) // step  # rows of the rendered set a pixel's filter reaches
    flat: Any = None
    for index, (first, last, lo, hi) in enumerate(bands(out_h, width, apron, env_size("MOTION_MAX_LANES"))):
        # band 0 keeps the frame's seed (a frame in one band is as it always was); later bands derive theirs
        band_seed = seed if index == 0 else mi.sample_tea_32(int(seed), BAND_SEED_BASE + index)[0]
        planes = _render_window(sample, scene, sensor, sampler, band_seed, spp, (width, height), (offset + step * lo, step, hi - lo))
        n_ch = len(planes)
        if flat is None:
            flat = dr.zeros(mi.Float, n_px * n_ch)
        # interleave the band's own rows into [H, W, C]: each element written exactly once (no conflicts)
        inner = dr.arange(mi.UInt32, (last - first) * width)
        source = inner + _opaque((first - lo) * width)
        target = inner + _opaque(first * width)
        for c, plane in enumerate(planes):
            dr.scatter(flat, dr.gather(mi.Float, plane, source), target * n_ch + c)
        dr.eval(flat)
    return mi.TensorXf(flat, shape=(out_h, width, n_ch))


BAND_SEED_BASE = 1 << 20  # bands' seeds apart from the passes' (sample_tea_32(seed, pass))


def bands(rows: int, width: int, apron: int, budget: int) -> list[tuple[int, int, int, int]]:
    """The row bands of an image of `rows` x `width` pixels under a budget of `budget`
    pixels a window: (first, last) rows each band delivers and (lo, hi) rows it renders,
    `apron` more on each side where the image has them (the filter of a delivered pixel
    reaches rows its band renders, never another band's). One band, (0, rows, 0, rows), when
    the image fits."""
    if rows * width <= budget:
        return [(0, rows, 0, rows)]
    inner = max(1, budget // max(width, 1) - 2 * apron)
    return [(a, min(rows, a + inner), max(0, a - apron), min(rows, a + inner + apron)) for a in range(0, rows, inner)]


def _opaque(value: int) -> Any:
    """`value` as a UInt32 the kernel reads at run time: a band's first row, its row count or
    its place in the frame differ from band to band, and as literals each band would trace
    and compile kernels of its own (485 for a 4x48 frame in 48 bands, against 16)."""
    return dr.opaque(mi.UInt32, value)


def _reach(rfilter: Any) -> int:
    """Pixels a reconstruction filter reaches beyond its own pixel."""
    return max(0, int(np.ceil(rfilter.radius() - 0.5)))


def _render_window(sample: SampleFn, scene: mi.Scene, sensor: Any, sampler: Any, seed: Any, spp: int, size: tuple[int, int], window: tuple[int, int, int]) -> list[Any]:
    """The normalised channel planes of `window` (offset, step, count) of a frame of `size`
    (width, height): rows offset, offset + step, ... count of them, in passes of at most the lane budget's samples per pixel (pass
    0 keeps `seed`, later ones derive theirs from it), summed in pass order."""
    width, height = size
    n_px = width * window[2]
    per_pass = max(1, min(spp, env_size("MOTION_MAX_LANES") // max(n_px, 1)))
    total: list[Any] = []
    for index, count in enumerate(stratified_passes(spp, per_pass)):
        pass_seed = seed if index == 0 else mi.sample_tea_32(int(seed), index)[0]
        acc, _ = render_pass(sample, scene, sensor, sampler, pass_seed, count, width, height, window)
        total = acc if index == 0 else [t + a for t, a in zip(total, acc)]
        dr.eval(total)
    weight = total[-1]
    inv = dr.select(weight > 0, dr.rcp(weight), 0.0)
    return [a * inv for a in total[:-1]]


def exact_count(n: int) -> bool:
    """Whether Mitsuba's `multijitter` sampler traces exactly n samples: it stratifies on
    a grid of floor(sqrt(n)) rows and rounds n up to fill the last column (32 -> 35)."""
    return n % math.isqrt(n) == 0


def stratified_passes(spp: int, per_pass: int) -> list[int]:
    """Split `spp` samples per pixel into passes of at most `per_pass` that the sampler
    traces exactly (`exact_count`): the count asked is the count traced, each pass
    stratified on its own grid. The fewest equal passes where up to two more than the
    least will do (32 -> 16 + 16, 96 -> 48 + 48, 192 -> 3 x 64, where one pass had
    rounded to 35, 99, 195), else the largest exact passes first (37 -> 36 + 1)."""
    least = -(-spp // per_pass)
    for k in range(least, least + 3):
        q, r = divmod(spp, k)
        counts = [q + 1] * r + [q] * (k - r)
        if q > 0 and all(exact_count(c) for c in counts):
            return counts
    counts = []
    left = spp
    while left > 0:
        c = min(per_pass, left)
        while not exact_count(c):
            c -= 1
        counts.append(c)
        left -= c
    return counts


def render_pass(sample: SampleFn, scene: mi.Scene, sensor: Any, sampler: Any, seed: Any, spp: int, width: int, height: int,
                rows: tuple[int, ...] = (0, 1)) -> tuple[list[Any], int]:
    """One pass of `spp` samples per pixel: per-pixel filter-weighted sums of every
    channel and of the weights (unnormalised), and the sample count actually used.
    `rows` (offset, step): only image rows offset, offset + step, ... below `height` (a
    field); (offset, step, count): count such rows (a band, `render`)."""
    offset, step = rows[0], rows[1]
    out_h = rows[2] if len(rows) > 2 else (height - offset + step - 1) // step
    n_px = width * out_h
    sampler.set_sample_count(spp)
    spp = int(sampler.sample_count())  # exact for the counts of `stratified_passes`
    sampler.set_samples_per_wavefront(spp)
    sampler.seed(seed, n_px * spp)

    # ray generation in Mitsuba's order of sampler dimensions
    pixel = dr.arange(mi.UInt32, n_px * spp) // spp
    px = mi.Vector2f(mi.Float(pixel % width), mi.Float(_opaque(offset) + step * (pixel // width)))
    film_pos = px + sampler.next_2d()
    time = sensor.shutter_open() + sampler.next_1d() * sensor.shutter_open_time()
    aperture = sampler.next_2d() if sensor.needs_aperture_sample() else mi.Point2f(0.5)
    ray, ray_weight = sensor.sample_ray_differential(time, 0.0, film_pos / mi.Vector2f(width, height), aperture)
    L, valid, aovs = sample(scene, sampler, ray, None, True)
    L = L * ray_weight
    channels = [L[0], L[1], L[2], dr.select(valid, 1.0, 0.0), *aovs]
    dr.eval(channels, film_pos)

    # reconstruction, one row of filter offsets oy at a time: every source pixel sums,
    # over its own samples in order, the filter-weighted channels it sends to each of
    # the pixels (ox, oy) away (`row_sums`: one kernel); then every target pixel
    # gathers those sums from its neighbours, offset by offset in a fixed order
    rfilter = sensor.film().rfilter()
    reach = _reach(rfilter)
    target = dr.arange(mi.UInt32, n_px)
    tx, ty = mi.Int32(target % width), mi.Int32(target // width)
    rows_here = dr.opaque(mi.Int32, out_h)  # a band's row count: the last band's may differ
    acc = [mi.Float(dr.zeros(mi.Float, n_px)) for _ in range(len(channels) + 1)]
    for oy in range(-reach, reach + 1):
        if oy % step:
            continue  # a row of the other field: not rendered
        sums = row_sums(rfilter, channels, film_pos, spp, width, n_px, oy, reach, (offset, step))
        dr.eval(sums)
        for ox in range(-reach, reach + 1):
            sx, sy = tx - ox, ty - oy // step  # the source pixel whose samples land here
            ok = (sx >= 0) & (sx < width) & (sy >= 0) & (sy < rows_here)
            src = mi.UInt32(dr.select(ok, sy * width + sx, 0))
            acc = [a + dr.gather(mi.Float, v, src, ok) for a, v in zip(acc, sums[ox + reach])]
        dr.eval(acc)
    return acc, spp


def row_sums(rfilter: Any, channels: list[Any], film_pos: Any, spp: int, width: int, n_px: int, oy: int, reach: int, rows: tuple[int, int] = (0, 1)) -> list[list[Any]]:
    """For every source pixel (one lane each) and each x offset ox in [-reach, reach]:
    the sums over the pixel's spp samples, in sample order, of channel * w and of w,
    where w = f(x) f(y) is the separable filter's weight of the sample for the pixel
    (ox, oy) away. Returns [2 reach + 1][channels + 1] arrays of n_px."""
    source = dr.arange(mi.UInt32, n_px)
    sx, sy = mi.Float(source % width), mi.Float(_opaque(rows[0]) + rows[1] * (source // width))  # frame rows (a field: every other)
    widths = 2 * reach + 1
    zero = [mi.Float(dr.zeros(mi.Float, n_px)) for _ in range(widths * (len(channels) + 1))]

    def body(s: Any, *acc: Any) -> tuple[Any, ...]:
        index = source * spp + s
        fx = dr.gather(mi.Float, film_pos.x, index)
        fy = dr.gather(mi.Float, film_pos.y, index)
        values = [dr.gather(mi.Float, c, index) for c in channels]
        wy = rfilter.eval(sy + (oy + 0.5) - fy)  # the target pixel's centre minus the sample
        out = list(acc)
        k = 0
        for ox in range(-reach, reach + 1):
            w = rfilter.eval(sx + (ox + 0.5) - fx) * wy
            for v in values:
                out[k] = out[k] + v * w
                k += 1
            out[k] = out[k] + w
            k += 1
        return (s + 1, *out)

    state = dr.while_loop((mi.UInt32(0), *zero), lambda s, *acc: s < spp, body, label="film_row")
    flat = list(state[1:])
    per = len(channels) + 1
    return [flat[i * per : (i + 1) * per] for i in range(widths)]
