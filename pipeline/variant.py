"""Choose the Mitsuba variant: CUDA on a GPU, LLVM where a working libLLVM exists, else scalar.

drjit's LLVM backend reads `DRJIT_LIBLLVM_PATH` once, when drjit is first imported, and
some LLVM builds (Debian's 14 and 15 with drjit 1.5) abort the whole process while
compiling a render kernel. So each candidate library is tried in a *subprocess* that
renders a tiny scene; the parent only imports drjit after the choice, with the variable
set. Results are remembered in the cache folder, keyed by the library file's identity
and the drjit version, so later commands pay nothing.

`python -m motion.pipeline.variant --check-llvm` exits 0 when a working LLVM is found
(the setup script uses it to decide whether to install libllvm19).
"""

from __future__ import annotations

import functools
import json
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, Mapping

from .cache import cache_root, file_stamp, package_file
from .errors import RendererError
from .write_policy import write_best_effort

VariantName = Literal["auto", "llvm_ad_rgb", "scalar_rgb", "cuda_ad_rgb"]

ENV_LLVM = "DRJIT_LIBLLVM_PATH"
_PROBE_TIMEOUT_S = 180.0

# A tiny but real render: the crash with LLVM 14/15 happens while compiling the path
# tracer's kernels (an unsupported `fminimum` instruction), not on simple arithmetic.
_PROBE_CODE = r"""
import sys
import mitsuba as mi
mi.set_variant(sys.argv[1])
import drjit as dr
scene = mi.load_dict(mi.cornell_box())
img = mi.render(scene, spp=1)
import numpy as np
v = float(np.asarray(img).mean())
if not (np.isfinite(v) and v > 0):
    raise SystemExit(f'render mean {v}')
print("ok")
"""


@dataclass(frozen=True)
class VariantChoice:
    """The Mitsuba variant chosen, the libLLVM it uses, why, and whether it is a fallback."""

    variant: str
    llvm_path: str | None
    reason: str
    fallback: bool = False


def _version(pkg: str) -> str:
    import importlib.metadata  # (here: 30 ms with its email parser; `motion info` asks, a rerun does not)

    try:
        return importlib.metadata.version(pkg)
    except importlib.metadata.PackageNotFoundError:
        return "missing"


def llvm_candidates() -> list[str | None]:
    """Libraries to try, best first. An explicit DRJIT_LIBLLVM_PATH is the only candidate.

    None means "let drjit search on its own" (its default lookup), tried last.
    """
    import fnmatch
    import glob

    explicit = os.environ.get(ENV_LLVM)
    if explicit:
        return [explicit]
    # each library folder is listed once and only its libLLVM* names are matched: globbing
    # the patterns one by one read /usr/lib/<triplet>/ (thousands of names) 30 times a
    # major version, 80 ms of every process's start
    listing: dict[str, list[str]] = {}

    def names(folder_pattern: str) -> list[tuple[str, str]]:
        out = []
        for folder in sorted(glob.glob(folder_pattern)):
            if folder not in listing:
                try:
                    listing[folder] = sorted(n for n in os.listdir(folder) if n.startswith("libLLVM"))
                except OSError:
                    listing[folder] = []
            out += [(folder, n) for n in listing[folder]]
        return out

    found: list[str] = []
    for major in range(30, 15, -1):
        patterns = [
            (f"/usr/lib/llvm-{major}/lib", "libLLVM.so.*"),
            (f"/usr/lib/llvm-{major}/lib", f"libLLVM-{major}.so"),
            ("/usr/lib/*-linux-gnu", f"libLLVM.so.{major}*"),
            ("/usr/lib/*-linux-gnu", f"libLLVM-{major}.so*"),
            ("/usr/lib64", f"libLLVM.so.{major}*"),
            ("/usr/lib64", f"libLLVM-{major}.so"),
        ]
        for folder_pattern, name_pattern in patterns:
            for folder, name in names(folder_pattern):
                if fnmatch.fnmatchcase(name, name_pattern):
                    real = os.path.realpath(os.path.join(folder, name))
                    if real not in found:
                        found.append(real)
    return [*found, None]


def _probe_key(variant: str, lib: str | None) -> str:
    ident = "default"
    if lib:
        try:
            st = os.stat(lib)
            ident = f"{os.path.realpath(lib)}:{st.st_size}:{int(st.st_mtime)}"
        except OSError:
            ident = f"{lib}:missing"
    # each package's installed build by its file's stamp (cache.package_file)
    builds = [file_stamp(p) if (p := package_file(name)) is not None else f"{name}:missing" for name in ("drjit", "mitsuba")]
    return f"{variant}|{ident}|drjit {builds[0]}|mitsuba {builds[1]}"


def _probe_cache_file() -> Path:
    return cache_root() / "variant-probe.json"


def _load_probe_cache() -> dict[str, bool]:
    try:
        return dict(json.loads(_probe_cache_file().read_text()))
    except (OSError, ValueError):
        return {}


def _store_probe(key: str, ok: bool) -> None:
    cache = _load_probe_cache()
    cache[key] = ok
    # a read-only or full cache only costs a re-probe next time
    write_best_effort(_probe_cache_file(), json.dumps(cache, indent=1, sort_keys=True).encode())


def probe(variant: str, lib: str | None = None, use_cache: bool = True) -> bool:
    """Does `variant` render a tiny scene in a fresh process with this libLLVM?"""
    import subprocess

    if lib is not None and not os.path.exists(lib):
        return False
    key = _probe_key(variant, lib)
    if use_cache:
        cached = _load_probe_cache().get(key)
        if cached is not None:
            return cached
    env = dict(os.environ)
    env.pop(ENV_LLVM, None)
    if lib:
        env[ENV_LLVM] = lib
    try:
        proc = subprocess.run(
            [sys.executable, "-c", _PROBE_CODE, variant],
            env=env,
            capture_output=True,
            text=True,
            timeout=_PROBE_TIMEOUT_S,
        )
        ok = proc.returncode == 0 and "ok" in proc.stdout
    except (subprocess.TimeoutExpired, OSError):
        ok = False
    _store_probe(key, ok)
    return ok


def gpu_devices(listing: str | None = None, env: Mapping[str, str] | None = None) -> list[str]:
    """The GPUs this process may use, as CUDA_VISIBLE_DEVICES names them: that variable's
    entries when it is set (empty, or from an entry starting with '-' on: none, as CUDA
    reads it), else one index per GPU `nvidia-smi -L` lists (`listing`: its output, given
    by tests; none when nvidia-smi is absent or fails)."""
    env = os.environ if env is None else env
    if "CUDA_VISIBLE_DEVICES" in env:
        out = []
        for entry in (e.strip() for e in env["CUDA_VISIBLE_DEVICES"].split(",")):
            if not entry or entry.startswith("-"):
                break
            out.append(entry)
        return out
    if listing is None:
        listing = _nvidia_smi_listing(os.environ.get("PATH", ""))
    return [str(k) for k, _ in enumerate(line for line in listing.splitlines() if line.startswith("GPU "))]


@functools.lru_cache(maxsize=4)
def _nvidia_smi_listing(path: str) -> str:
    """`nvidia-smi -L`'s output ('' when it is not on `path` or fails), once per process."""
    import shutil
    import subprocess

    smi = shutil.which("nvidia-smi", path=path)
    if smi is None:
        return ""
    try:
        proc = subprocess.run([smi, "-L"], capture_output=True, text=True, timeout=20)
    except (OSError, subprocess.TimeoutExpired):
        return ""
    return proc.stdout if proc.returncode == 0 else ""


def device_of(variant: str) -> str:
    """What a worker renders on, for the report: `cuda:<its CUDA_VISIBLE_DEVICES, else 0>`
    on a CUDA variant, else `cpu`."""
    if variant.startswith("cuda"):
        return f"cuda:{os.environ.get('CUDA_VISIBLE_DEVICES') or '0'}"
    return "cpu"


def _gpu_present() -> bool:
    import glob

    if "CUDA_VISIBLE_DEVICES" in os.environ:  # the user's choice of GPUs: none means none
        return bool(gpu_devices())
    return any(os.path.exists(p) for p in ("/dev/nvidia0", "/dev/nvidiactl")) or bool(
        glob.glob("/usr/lib/*-linux-gnu/libcuda.so*")
    )


def find_llvm(use_cache: bool = True) -> str | None | Literal[False]:
    """The first libLLVM that renders; None = drjit's own lookup works; False = none works."""
    for lib in llvm_candidates():
        if probe("llvm_ad_rgb", lib, use_cache=use_cache):
            return lib
    return False


def choose(requested: str = "auto", use_cache: bool = True) -> VariantChoice:
    """Pick the variant for `requested` without importing drjit in this process."""
    if requested == "scalar_rgb":
        return VariantChoice("scalar_rgb", None, "requested")
    if requested == "cuda_ad_rgb":
        if probe("cuda_ad_rgb", None, use_cache=use_cache):
            return VariantChoice("cuda_ad_rgb", None, "requested")
        raise RendererError("variant cuda_ad_rgb was requested but no working CUDA device was found")
    if requested == "auto" and _gpu_present() and probe("cuda_ad_rgb", None, use_cache=use_cache):
        return VariantChoice("cuda_ad_rgb", None, "GPU found")
    lib = find_llvm(use_cache=use_cache)
    if lib is not False:
        return VariantChoice("llvm_ad_rgb", lib, "LLVM library renders" if lib else "drjit's default LLVM renders")
    tried = ", ".join(c or "drjit default" for c in llvm_candidates())
    if requested == "llvm_ad_rgb":
        raise RendererError(
            f"variant llvm_ad_rgb was requested but no libLLVM renders (tried: {tried}); "
            "install Debian's libllvm19 (tools/setup.sh does) or set DRJIT_LIBLLVM_PATH"
        )
    return VariantChoice(
        "scalar_rgb",
        None,
        f"no working LLVM library (tried: {tried})",
        fallback=True,
    )


_active: VariantChoice | None = None


def activate(requested: str = "auto", threads: int | None = None, quiet: bool = False) -> VariantChoice:
    """Choose, export DRJIT_LIBLLVM_PATH, then import Mitsuba and set the variant once.

    Safe to call repeatedly in one process; the first choice stays (drjit cannot switch
    LLVM libraries after import). Warns once on stderr when falling back to scalar.
    """
    global _active
    if _active is not None:
        if requested not in ("auto", _active.variant):
            raise RendererError(
                f"this process already renders with {_active.variant}; cannot switch to {requested}"
            )
        return _active
    choice = choose(requested)
    if choice.llvm_path:
        os.environ[ENV_LLVM] = choice.llvm_path
    elif choice.variant == "scalar_rgb":
        os.environ.pop(ENV_LLVM, None)  # a broken library would only make drjit complain
    if choice.fallback and not quiet:
        warn_fallback(choice)
    os.environ.setdefault("DRJIT_CACHE_DIR", str(cache_root() / "kernels"))
    import drjit as dr
    import mitsuba as mi

    if threads is not None and choice.variant != "scalar_rgb":
        dr.set_thread_count(max(1, int(threads)))
    mi.set_variant(choice.variant)
    _active = choice
    return choice


def warn_fallback(choice: VariantChoice) -> None:
    """The one-line warning for the scalar fallback (printed once, by the main process)."""
    print(
        f"warning: {choice.reason}; rendering with scalar_rgb (slow; stochastic motion blur "
        "becomes sub-frame accumulation). Install Debian's libllvm19 (tools/setup.sh does).",
        file=sys.stderr,
    )


def info() -> dict[str, object]:
    """What `motion info` prints: variant choice, LLVM, threads, caches, versions."""
    choice = choose("auto")
    llvm_version = None
    if choice.llvm_path:
        import re

        found = re.search(r"(\d+(?:\.\d+)*)", os.path.basename(choice.llvm_path))
        llvm_version = found.group(1) if found else None
    return {
        "variant": choice.variant,
        "reason": choice.reason,
        "fallback": choice.fallback,
        "llvm_library": choice.llvm_path,
        "llvm_version": llvm_version,
        "threads": os.cpu_count(),
        "cache_root": str(cache_root()),
        "kernel_cache": os.environ.get("DRJIT_CACHE_DIR", str(cache_root() / "kernels")),
        "asset_cache": str(cache_root() / "assets"),
        "python": sys.version.split()[0],
        "packages": {p: _version(p) for p in ("motion-farm", "mitsuba", "drjit", "OpenEXR", "numpy", "scipy", "av", "dask", "distributed", "pydantic")},
    }


def main(argv: list[str] | None = None) -> int:
    """`python -m motion.pipeline.variant --check-llvm`: exit 0 when a working LLVM is found."""
    args = sys.argv[1:] if argv is None else argv
    if args == ["--check-llvm"]:
        lib = find_llvm(use_cache=False)
        if lib is False:
            print("no working libLLVM for drjit's LLVM backend")
            return 1
        print(f"working libLLVM: {lib or 'drjit default lookup'}")
        return 0
    print(json.dumps(info(), indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


def load_dict(d: dict[str, Any]) -> Any:
    """`mi.load_dict` with at least 2 drjit threads while it runs.

    Mitsuba reads OpenEXR files (environment maps, bitmap textures) by handing OpenEXR's
    line-block tasks to drjit's thread pool and waiting for them; drjit's thread count
    includes the calling thread, so a pool set to 1 thread (2 local workers on 2 cores, or
    `--threads 1`) has no thread to run them and the read deadlocks. The count goes back
    to what the job planned before rendering, so the plan and the report stay true."""
    import drjit as dr
    import mitsuba as mi

    threads = dr.thread_count()
    if threads >= 2 or mi.variant() == "scalar_rgb":
        return mi.load_dict(d)
    dr.set_thread_count(2)
    try:
        return mi.load_dict(d)
    finally:
        dr.set_thread_count(threads)
