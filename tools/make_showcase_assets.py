"""Generate the showcase scenes' lighting and ground assets procedurally (no downloads).

    python tools/make_showcase_assets.py [scenes/assets]

Writes, deterministically (fixed seeds):

- ``sky.hdr``: a 1024x512 lat-long HDR sky (Radiance RGBE, not OpenEXR: Mitsuba reads an EXR
  through OpenEXR tasks on drjit's thread pool, and a farm worker with one drjit thread,
  which is 2 workers on 2 cores, has no pool thread to run them and hangs; RGBE is read
  on the calling thread) in Mitsuba's envmap convention (+Y up; the
  direction d sits at u = atan2(d.x, -d.z) / 2 pi, v = acos(d.y) / pi: u = 0 looks along -Z,
  u = 1/4 along +X). A clear afternoon
  sky: a saturated zenith fading to a pale horizon haze within a few degrees of the horizon
  (so the lower sky stays blue through a tone-mapped view), a forward-scattering glow around the
  sun (a Henyey-Greenstein lobe) and the sun's disk, a few soft clouds, and below the horizon
  a dim haze that the showcase ground meets at the horizon. The sun's energy is carried by a
  `directional` light in the scenes (its direction is printed); the disk in the map is only
  bright enough to be seen in reflections, so the sun is not counted twice.
- ``grass.jpg``: a 1024x1024 tileable meadow (clumps, blades, bare patches), linear
  albedo about 0.1-0.3 stored as sRGB.
- ``water.jpg``: a 1024x1024 tileable sea colour with ripples and foam-free streaks.
- ``stone.jpg``: 1024x1024 tileable flagstones (irregular slabs, mortar, grain).

Every texture is made from periodic noise (white noise filtered in the Fourier domain), so
it tiles without a seam.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

SUN_AZIMUTH_DEG = 40.0    # world direction to the sun: from -Z towards +X (an untransformed map)
SUN_ELEVATION_DEG = 25.0


def sun_direction() -> np.ndarray:
    """Unit vector from the ground towards the sun (the directional light travels along -it)."""
    az, el = np.radians(SUN_AZIMUTH_DEG), np.radians(SUN_ELEVATION_DEG)
    return np.array([np.sin(az) * np.cos(el), np.sin(el), -np.cos(az) * np.cos(el)])


def periodic_noise(n: int, beta: float, seed: int, band: tuple[float, float] = (1.0, 1e9),
                   stretch: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """Tileable n x n noise with a 1/f^beta spectrum inside `band` (cycles per tile), unit std."""
    rng = np.random.default_rng(seed)
    white = rng.standard_normal((n, n))
    fy = np.fft.fftfreq(n)[:, None] * n * stretch[0]
    fx = np.fft.fftfreq(n)[None, :] * n * stretch[1]
    f = np.hypot(fx, fy)
    f[0, 0] = 1.0
    amp = f ** (-beta / 2.0) * ((f >= band[0]) & (f <= band[1]))
    amp[0, 0] = 0.0
    out = np.real(np.fft.ifft2(np.fft.fft2(white) * amp))
    return out / (out.std() + 1e-12)


def _srgb(linear: np.ndarray) -> np.ndarray:
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def _save_jpg(path: Path, linear_rgb: np.ndarray) -> None:
    from PIL import Image

    img = (np.clip(_srgb(linear_rgb), 0, 1) * 255 + 0.5).astype(np.uint8)
    Image.fromarray(img).save(path, quality=88, optimize=True)


def sky(width: int = 1024, height: int = 512) -> np.ndarray:
    """The lat-long sky radiance (float32, height x width x 3), W sr^-1 m^-2 per channel."""
    v = (np.arange(height) + 0.5) / height
    u = (np.arange(width) + 0.5) / width
    theta = v[:, None] * np.pi
    phi = u[None, :] * 2 * np.pi
    d = np.stack(np.broadcast_arrays(np.sin(phi) * np.sin(theta), np.cos(theta) + 0 * phi,
                                     -np.cos(phi) * np.sin(theta)), axis=-1)
    up = d[..., 1]
    s = sun_direction()
    cos_g = np.clip(d @ s, -1.0, 1.0)

    zenith = np.array([0.10, 0.22, 0.62])
    horizon = np.array([0.55, 0.68, 0.92])
    h = np.clip(up, 0.0, 1.0)
    # haze thickens towards the horizon, within a few degrees of it: the lower sky that the
    # showcase cameras see stays blue through the deliverables' ACES 2.0 view (with a haze
    # scale of 0.22 and a paler horizon it came out grey: docs/showcase.md)
    t = np.exp(-h / 0.08)[..., None]
    base = zenith + (horizon - zenith) * t
    # brighter sky on the sun's side (Rayleigh-ish), then the Mie glow (Henyey-Greenstein)
    base = base * (1.0 + 0.25 * (cos_g[..., None] + 1.0))
    g = 0.8
    hg = (1 - g * g) / (4 * np.pi * np.power(1 + g * g - 2 * g * cos_g, 1.5))
    glow = np.array([1.0, 0.85, 0.6]) * (0.6 * hg)[..., None]
    radiance = base + glow * (up > -0.02)[..., None]

    # soft clouds: thresholded periodic noise, only in the sky, thinning to the zenith
    n = periodic_noise(max(width, height), 3.0, seed=11, band=(2, 48))[:height, :width]
    cover = np.clip((n - 0.9) / 1.2, 0, 1) * np.clip(h / 0.05, 0, 1) * np.exp(-h / 0.5)
    cloud = np.array([1.05, 1.02, 1.0]) * (0.9 + 0.5 * np.clip(cos_g, 0, 1))[..., None]
    radiance = radiance * (1 - cover[..., None]) + cloud * cover[..., None]

    # the sun's disk (0.27 degrees of angular radius), limb-darkened
    ang = np.arccos(cos_g)
    r = np.radians(0.27 * 2.0)   # two pixels wide at this resolution, so it is not lost
    disk = np.clip(1 - (ang / r) ** 2, 0, 1) ** 0.4
    radiance = radiance + np.array([3.0, 2.8, 2.4]) * disk[..., None]

    # below the horizon: haze falling off to a dim ground within a few degrees
    below = np.clip(-up, 0.0, 1.0)
    ground = np.array([0.10, 0.11, 0.10])
    fade = np.exp(-below / 0.03)[..., None]
    under = ground + (horizon - ground) * fade
    radiance = np.where((up < 0)[..., None], under, radiance)
    return radiance.astype(np.float32)


def grass(n: int = 1024) -> np.ndarray:
    """A tileable meadow albedo (linear RGB) covering about 4 m: clumps, blades, soil."""
    patches = periodic_noise(n, 3.0, seed=1, band=(1, 40))           # metre-scale colour drift
    clumps = periodic_noise(n, 2.0, seed=2, band=(8, 160))           # tufts
    blades = periodic_noise(n, 0.5, seed=3, band=(60, 512), stretch=(0.25, 1.0))  # streaks
    soil = np.clip((periodic_noise(n, 2.5, seed=4, band=(3, 60)) - 1.3) * 1.5, 0, 1)
    green = np.array([0.10, 0.20, 0.045])
    dry = np.array([0.24, 0.23, 0.09])
    dirt = np.array([0.16, 0.12, 0.08])
    mix = np.clip(0.5 + 0.25 * patches, 0, 1)[..., None]
    col = green * (1 - mix) + dry * mix
    shade = np.clip(1.0 + 0.22 * clumps + 0.28 * blades, 0.35, 1.7)[..., None]
    col = col * shade
    col = col * (1 - soil[..., None]) + dirt * soil[..., None] * shade
    return col


def water(n: int = 1024) -> np.ndarray:
    """A tileable sea colour (linear RGB) covering about 8 m: swell shading and ripples."""
    swell = periodic_noise(n, 3.0, seed=21, band=(1, 12), stretch=(1.0, 0.4))
    ripple = periodic_noise(n, 1.5, seed=22, band=(20, 300), stretch=(1.0, 0.35))
    deep = np.array([0.010, 0.045, 0.060])
    shallow = np.array([0.030, 0.10, 0.11])
    mix = np.clip(0.5 + 0.3 * swell, 0, 1)[..., None]
    col = deep * (1 - mix) + shallow * mix
    return col * np.clip(1 + 0.35 * ripple, 0.4, 1.8)[..., None]


def stone(n: int = 1024, cells: int = 6) -> np.ndarray:
    """Tileable flagstones (linear RGB) covering about 3 m: Voronoi slabs, mortar, grain."""
    rng = np.random.default_rng(31)
    pts = rng.random((cells * cells, 2))
    tone = rng.uniform(0.75, 1.25, cells * cells)
    y, x = (np.mgrid[0:n, 0:n] + 0.5) / n
    warp = 0.02 * periodic_noise(n, 3.0, seed=32, band=(2, 10))
    x, y = x + warp, y + 0.8 * warp
    d1 = np.full((n, n), 9.0)
    d2 = np.full((n, n), 9.0)
    idx = np.zeros((n, n), dtype=int)
    for k, (px, py) in enumerate(pts):
        for ox in (-1, 0, 1):
            for oy in (-1, 0, 1):
                d = np.hypot(x - px - ox, y - py - oy)
                closer = d < d1
                d2 = np.where(closer, d1, np.minimum(d2, d))
                idx = np.where(closer, k, idx)
                d1 = np.where(closer, d, d1)
    edge = np.clip((d2 - d1) / 0.012, 0, 1)[..., None]             # 0 in the mortar joint
    grain = periodic_noise(n, 1.0, seed=33, band=(40, 512))
    blotch = periodic_noise(n, 2.5, seed=34, band=(2, 60))
    slab = np.array([0.36, 0.33, 0.29]) * tone[idx][..., None]
    slab = slab * np.clip(1 + 0.10 * grain + 0.15 * blotch, 0.5, 1.5)[..., None]
    mortar = np.array([0.12, 0.11, 0.10])
    return slab * edge + mortar * (1 - edge)


def write_hdr(path: Path, rgb: np.ndarray) -> None:
    """A Radiance RGBE (.hdr) image, written by Mitsuba's own Bitmap writer."""
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    mi.Bitmap(np.ascontiguousarray(rgb, dtype=np.float32)).write(str(path))


def main(argv: list[str]) -> int:
    """Write every asset into the folder given (default scenes/assets)."""
    out = Path(argv[1]) if len(argv) > 1 else Path(__file__).resolve().parents[1] / "scenes" / "assets"
    out.mkdir(parents=True, exist_ok=True)
    write_hdr(out / "sky.hdr", sky())
    _save_jpg(out / "grass.jpg", grass())
    _save_jpg(out / "water.jpg", water())
    _save_jpg(out / "stone.jpg", stone())
    s = sun_direction()
    print(f"wrote sky.hdr grass.jpg water.jpg stone.jpg to {out}")
    print(f"sun: directional light direction [{-s[0]:.4f}, {-s[1]:.4f}, {-s[2]:.4f}]")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
