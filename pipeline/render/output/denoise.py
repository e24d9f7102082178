"""Denoising a frame in the worker: Intel Open Image Denoise (OIDN) guided by the first-hit
albedo and shading-normal passes (docs/denoise.md).

The worker renders the noisy beauty together with the guides (the film averages them over
each pixel's samples and shutter times exactly as it averages the beauty, so the guides are
motion-blurred like it), then `denoise_frame` runs OIDN's `RT` filter on them and returns
the denoised RGBA plus the layers the EXR keeps: the noisy beauty (`noisy`), the guides
(`albedo`, `N`) and the header attributes that say so.

The binding is `mitsuba-oidn` (nanobind, made for Dr.Jit: OIDN runs on Dr.Jit's own thread
pool instead of a second oneTBB pool). OIDN's filter gives the same bits whatever the
number of threads once its HDR input scale is given (`input_scale`, computed here in a
fixed order); its own auto-exposure is a parallel sum whose last bits follow the threads.
A missing or broken library is a `DenoiserUnavailableError`: one line naming the package,
raised before the first frame (`check_available`, a probe in a subprocess) or in the worker.

On a CUDA variant the filter runs on OIDN's CUDA device where OIDN has one (`pick_device`;
the frame's header names the device), else on the CPU with one line saying so; a CUDA
device that fails to start or to run falls back to the CPU the same way, never aborting
the frame. CPU variants keep the CPU device (and their bits). OptiX's own denoiser is not
used: where the driver lacks its weights (`nvoptix.bin`) it aborts the whole process.
"""

from __future__ import annotations

import functools
import json
import os
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

from ...errors import RendererError

if TYPE_CHECKING:  # numpy is imported where a frame is denoised, not where the denoiser is checked
    import numpy as np

PACKAGE = "mitsuba-oidn"  # the PyPI name
MODULE = "mitsuba_oidn"  # its import name
GUIDES = ("albedo", "normal")  # integrator AOVs the denoiser reads (names of the AOV table, aovs.py)
NOISY_LAYER = "noisy"  # the EXR layer that keeps the undenoised beauty (RGBA)


class DenoiserUnavailableError(RendererError):
    """`render.denoise: oidn` was asked for, but the OIDN binding cannot be imported or run."""


def integrator_aovs(scene: Any) -> list[str]:
    """The AOVs the integrator computes for `scene`: the user's `output.aovs` (each once),
    plus the denoiser's guides when `render.denoise` is on, plus the motion vectors the
    temporal mode reprojects with."""
    wanted = list(dict.fromkeys(scene.output.aovs))
    if scene.render.denoise != "off":
        wanted += [a for a in GUIDES if a not in wanted]
    if scene.render.temporal != "off" and "motion" not in wanted:
        wanted.append("motion")
    return wanted


def _unavailable(reason: str) -> DenoiserUnavailableError:
    reason = " ".join(str(reason).split())  # one line
    return DenoiserUnavailableError(f"render.denoise: oidn needs the Python package {PACKAGE} (pip install {PACKAGE}), which failed: {reason}")


# A real denoise of a tiny image: an import that succeeds but a library that cannot run
# (wrong CPU, missing shared object loaded lazily) fails here too.
_PROBE = """
import json, numpy as np, mitsuba_oidn as oidn
dev = oidn.Device(oidn.DeviceType.CPU)
img = np.full((8, 8, 3), 0.5, np.float32)
out = oidn.denoise(img, img, img * 0 + np.float32([0, 0, 1]), hdr=True, device=dev)
if out.shape != (8, 8, 3) or not np.isfinite(out).all():
    raise SystemExit(f"the probe's denoised image is wrong: shape {out.shape}")
print(json.dumps({"version": oidn.__version__, "oidn": oidn.oidn_version(), "device": str(dev.type).split(".")[-1]}))
"""


def _probe_entry() -> Path | None:
    """Where the probe's answer for this binding is kept (cache.STORES["probes"]): keyed by
    this Python, the files of the binding's package and of drjit's and mitsuba's, whose
    libraries it loads (name, size, modification time: a reinstall or another build is
    another key), and this machine (its name and architecture: a cache root shared by other
    machines is not believed for this one). None when the binding is not installed."""
    from ...cache import STORES, package_stamps

    listed = [stamp for name in (MODULE, "drjit", "mitsuba") for stamp in package_stamps(name)]
    if listed[0] == f"{MODULE}:absent" or any(s.endswith(":unreadable") for s in listed):
        return None
    store = STORES["probes"]
    key = store.key(os.path.realpath(sys.executable), *listed, os.uname().nodename, os.uname().machine)  # (the host's name, as socket gives it)
    return store.path(key, stem="oidn", suffix=".json")


def _run_probe() -> dict[str, Any]:
    """The probe itself, in a subprocess: {version, oidn, device}, or {error}."""
    import subprocess  # (here: a kept probe, which every rerun reads, needs no process)

    try:
        proc = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, timeout=120)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return {"error": f"{type(exc).__name__}: {exc}"}
    if proc.returncode != 0:
        lines = [ln for ln in proc.stderr.strip().splitlines() if ln.strip()]
        return {"error": lines[-1] if lines else f"exit status {proc.returncode}"}
    try:
        return dict(json.loads(proc.stdout.strip().splitlines()[-1]))
    except (ValueError, IndexError):
        return {"error": f"unexpected probe output {proc.stdout[-200:]!r}"}


@functools.lru_cache(maxsize=1)
def probe() -> dict[str, Any]:
    """Import and run the binding in a subprocess (the farm's main process never loads
    Dr.Jit's libraries): {version, oidn, device}, or {error}. An answer that the binding
    works is kept in the cache layer (`_probe_entry`) and read by the next process instead
    of probing again; a failure is never kept (a fixed install is seen at once)."""
    from ...cache import STORES

    entry = _probe_entry()
    data = STORES["probes"].read(entry, 4096) if entry is not None else None
    try:
        kept = json.loads(data) if data is not None else None
    except ValueError:
        kept = None
    if isinstance(kept, dict) and set(kept) == {"version", "oidn", "device"} and all(isinstance(v, str) for v in kept.values()):
        return kept
    found = _run_probe()
    if entry is not None and "error" not in found:
        STORES["probes"].put(entry, json.dumps(found, sort_keys=True).encode(), best_effort=True, doing="keeping the denoiser probe's answer")
    return found


def check_available() -> dict[str, Any]:
    """The binding's versions, or DenoiserUnavailableError (one line, names the package)."""
    found = probe()
    if "error" in found:
        raise _unavailable(found["error"])
    return found


def describe(found: Mapping[str, Any]) -> str:
    """'Intel Open Image Denoise 2.5.1 (mitsuba-oidn 0.1.2, CPU)' for headers and `motion info`."""
    return f"Intel Open Image Denoise {found['oidn']} ({PACKAGE} {found['version']}, {found.get('device', 'CPU')})"


def pick_device(variant: str, devices: Sequence[str]) -> tuple[str, str | None]:
    """The OIDN device type for frames rendered with `variant`, given the device types
    OIDN lists here (`devices`, e.g. ["CUDA", "CPU"]): CUDA for a CUDA variant where OIDN
    has it, else CPU; and the line that says why a CUDA variant denoises on the CPU (None
    when nothing fell back)."""
    if not variant.startswith("cuda"):
        return "CPU", None
    if "CUDA" in devices:
        return "CUDA", None
    return "CPU", f"denoise: {PACKAGE} has no CUDA device here (it lists {', '.join(devices) or 'none'}); denoising on the CPU"


def _fell_back(line: str) -> None:
    """Say once, on stderr, that the denoiser runs on the CPU instead of the GPU."""
    import logging

    logging.getLogger("motion").warning(f"motion: warning: {line}")


class Denoiser:
    """One OIDN device and a filter per image size and guide set, kept by the worker across
    frames (OIDN's filter setup is the expensive part). `variant`: the Mitsuba variant of
    the frames (default: the active one), which picks the device (`pick_device`)."""

    def __init__(self, variant: str | None = None) -> None:
        try:
            import mitsuba_oidn as oidn
        except Exception as exc:  # ImportError, OSError from a missing .so, ...
            raise _unavailable(f"{type(exc).__name__}: {exc}") from None
        self._oidn = oidn
        if variant is None:
            import mitsuba as mi

            variant = str(mi.variant() or "")
        kind, line = pick_device(variant, [str(p.type).split(".")[-1] for p in oidn.physical_devices()])
        self._device = None
        if kind == "CUDA":
            try:
                self._device = oidn.Device(oidn.DeviceType.CUDA)
            except Exception as exc:
                kind, line = "CPU", f"denoise: {PACKAGE}'s CUDA device failed to start ({type(exc).__name__}: {' '.join(str(exc).split())}); denoising on the CPU"
        if line is not None:
            _fell_back(line)
        if self._device is None:
            try:
                self._device = oidn.Device(oidn.DeviceType.CPU)
            except Exception as exc:
                raise _unavailable(f"{type(exc).__name__}: {exc}") from None
        self.kind = kind
        self.version = {"version": oidn.__version__, "oidn": oidn.oidn_version(), "device": kind}
        self._filters: dict[tuple[Any, ...], Any] = {}

    def _on_cpu(self, reason: str) -> None:
        """The CUDA device failed a frame: this and every later frame on the CPU."""
        _fell_back(f"denoise: {PACKAGE}'s CUDA device failed ({reason}); denoising on the CPU")
        self._device = self._oidn.Device(self._oidn.DeviceType.CPU)
        self._filters.clear()
        self.kind = "CPU"
        self.version = {**self.version, "device": "CPU"}

    def _filter(self, key: tuple[Any, ...]) -> Any:
        flt = self._filters.get(key)
        if flt is None:
            self._filters.clear()  # one frame size per job: keep one filter, bounded memory
            flt = self._device.new_filter("RT")
            flt.hdr = True  # linear radiance, unbounded
            flt.clean_aux = False  # guides are averaged over the samples: not noise-free
            flt.quality = self._oidn.Quality.High
            self._filters[key] = flt
        return flt

    def __call__(self, color: np.ndarray, albedo: np.ndarray | None = None, normal: np.ndarray | None = None) -> np.ndarray:
        """Denoise linear RGB [H, W, 3] with optional guides of the same size; float32 out."""
        import numpy as np

        color = np.ascontiguousarray(np.nan_to_num(color[..., :3], nan=0.0, posinf=0.0, neginf=0.0), dtype=np.float32)
        guides = []
        if albedo is not None:
            guides.append(("albedo", np.ascontiguousarray(np.clip(albedo[..., :3], 0.0, 1.0), dtype=np.float32)))
        if normal is not None:
            guides.append(("normal", np.ascontiguousarray(np.clip(normal[..., :3], -1.0, 1.0), dtype=np.float32)))
        if self.kind == "CUDA":
            try:
                return self._run(color, guides)
            except Exception as exc:  # OIDN reports its errors as exceptions
                self._on_cpu(f"{type(exc).__name__}: {' '.join(str(exc).split())}")
        try:
            return self._run(color, guides)
        except Exception as exc:
            raise _unavailable(f"{type(exc).__name__}: {exc}") from None

    def _run(self, color: np.ndarray, guides: list[tuple[str, np.ndarray]]) -> np.ndarray:
        """One execution of the frame size's filter on the device."""
        import numpy as np

        h, w = color.shape[:2]
        flt = self._filter((h, w, tuple(name for name, _ in guides)))
        # OIDN's own HDR auto-exposure sums over the image in parallel, in an order that
        # depends on the thread count (1 vs 2 threads differed by a half-float ulp in 35
        # pixels of a 160x90 frame); the same key value computed here, in a fixed order,
        # makes the output independent of the threads (checked at 1, 2 and 3)
        flt.input_scale = input_scale(color)
        out = np.zeros_like(color)
        held = [self._bind(flt, "color", color), *(self._bind(flt, name, image) for name, image in guides)]
        staged_out = self._bind(flt, "output", out, staged=False)
        flt.execute()
        del held
        if staged_out is not None:
            out[...] = np.from_dlpack(staged_out.view("float32", out.shape))
        return out

    def _bind(self, flt: Any, name: str, image: np.ndarray, staged: bool = True) -> Any:
        """Bind a float32 [H, W, 3] array: as it is where the device can read it (the CPU),
        else through a buffer of the device (copied in for an input; host memory the device
        writes for the output). Returns the buffer (None when bound as it is)."""
        oidn = self._oidn
        if self._device.can_share(image):
            flt.set_image(name, image)
            return None
        h, w, c = image.shape
        buf = self._device.new_buffer(image.nbytes, oidn.Storage.Device if staged else oidn.Storage.Host)
        if staged:
            buf.write(image)
        flt.set_image(name, buf, format=oidn.Format(oidn.Format.Float.value + c - 1), width=w, height=h, pixel_stride=c * image.itemsize)
        return buf


def input_scale(color: np.ndarray) -> float:
    """HDR exposure for the denoiser: maps the image's log-average luminance to 0.18 (the
    photographic key OIDN's auto-exposure also aims at); 1 for a black image."""
    import numpy as np

    lum = color[..., :3].astype(np.float64) @ np.array([0.2126, 0.7152, 0.0722])
    lit = lum[lum > 1e-8]
    if lit.size == 0:
        return 1.0
    return float(0.18 / np.exp(np.log(lit).mean()))


_DENOISER: list[Denoiser] = []


def denoiser() -> Denoiser:
    """The process's denoiser (made on first use)."""
    if not _DENOISER:
        _DENOISER.append(Denoiser())
    return _DENOISER[0]


def denoise_frame(rgba: np.ndarray, aovs: Mapping[str, np.ndarray], color: np.ndarray | None = None) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, Any]]:
    """The worker step: denoise a rendered frame with its albedo and normal guides.

    rgba: the noisy beauty [H, W, 4]; aovs: the frame's layers (the albedo and normal
    layers, `albedo` and `N`, are used when present); color: what to denoise instead of
    rgba's RGB (the temporal mode's blend).
    Returns (denoised RGBA with the noisy alpha, layers + `noisy`, header attributes)."""
    import numpy as np

    from ..kernel.aovs import layer  # (here: the main process checks the denoiser without the AOV table)

    d = denoiser()
    albedo, normal = aovs.get(layer("albedo")), aovs.get(layer("normal"))
    t0 = time.perf_counter()
    rgb = d(rgba[..., :3] if color is None else color, albedo, normal)
    seconds = time.perf_counter() - t0
    out = np.concatenate([rgb, rgba[..., 3:4].astype(np.float32)], axis=2)
    layers = dict(aovs)
    layers[NOISY_LAYER] = np.asarray(rgba, dtype=np.float32)
    used = [layer(name) for name, g in (("albedo", albedo), ("normal", normal)) if g is not None]
    meta = {
        "denoise": "oidn",
        "denoiser": describe(d.version),
        "denoise_guides": ",".join(used) or "none",
        "denoise_seconds": float(seconds),
        "rgba": "denoised",
        "noisy_layer": NOISY_LAYER,
    }
    return out, layers, meta
