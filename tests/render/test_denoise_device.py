"""Denoising on the GPU (issue 35): a CUDA variant's frames go to OIDN's CUDA device where OIDN
has one, else to the CPU with one line, never an abort; CPU variants keep the CPU device.
Checked here with the OIDN this machine has (a CPU), the CUDA path's buffer staging run on
the CPU device's own buffers."""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
import pytest

oidn = pytest.importorskip("mitsuba_oidn", reason="denoising needs mitsuba-oidn (pip install mitsuba-oidn)")


def _frame() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(35)
    color = (rng.random((18, 32, 3)) * 2).astype(np.float32)
    albedo = rng.random((18, 32, 3)).astype(np.float32)
    normal = (rng.random((18, 32, 3)) * 2 - 1).astype(np.float32)
    return color, albedo, normal


def test_the_device_follows_the_variant() -> None:
    from motion.pipeline.render.output.denoise import pick_device

    assert pick_device("cuda_ad_rgb", ["CUDA", "CPU"]) == ("CUDA", None)
    assert pick_device("llvm_ad_rgb", ["CUDA", "CPU"]) == ("CPU", None)  # a CPU render keeps its bits
    assert pick_device("scalar_rgb", ["CPU"]) == ("CPU", None)
    kind, line = pick_device("cuda_ad_rgb", ["CPU"])
    assert kind == "CPU" and line is not None and "no CUDA device" in line and "denoising on the CPU" in line and "\n" not in line


def test_a_cuda_frame_is_denoised_on_what_works_here(caplog: pytest.LogCaptureFixture) -> None:
    from motion.pipeline.render.output.denoise import Denoiser, describe

    color, albedo, normal = _frame()
    cpu = Denoiser("llvm_ad_rgb")
    with caplog.at_level(logging.WARNING, logger="motion"):
        gpu = Denoiser("cuda_ad_rgb")
    has_cuda = any(str(p.type).endswith("CUDA") for p in oidn.physical_devices())
    if has_cuda:
        assert gpu.kind == "CUDA" and "CUDA" in describe(gpu.version)
        assert np.allclose(gpu(color, albedo, normal), cpu(color, albedo, normal), atol=0.05)
    else:
        assert gpu.kind == "CPU" and describe(gpu.version).endswith("CPU)")
        lines = [r.getMessage() for r in caplog.records if "denoise" in r.getMessage()]
        assert len(lines) == 1 and "no CUDA device" in lines[0]
        assert np.array_equal(gpu(color, albedo, normal), cpu(color, albedo, normal))


class _Unshared:
    """A real OIDN device that says it cannot read host arrays, as a CUDA device says of
    NumPy's: the images then go through the device's own buffers."""

    def __init__(self, device: Any) -> None:
        self.device = device

    def can_share(self, image: Any) -> bool:
        return False

    def __getattr__(self, name: str) -> Any:
        return getattr(self.device, name)


def test_images_staged_through_device_buffers_denoise_to_the_same_bits() -> None:
    from motion.pipeline.render.output.denoise import Denoiser

    color, albedo, normal = _frame()
    shared = Denoiser("llvm_ad_rgb")(color, albedo, normal)
    staged = Denoiser("llvm_ad_rgb")
    staged._device = _Unshared(staged._device)
    assert np.array_equal(staged(color, albedo, normal), shared)
    assert np.array_equal(staged(color * 0.5, albedo, normal), Denoiser("llvm_ad_rgb")(color * 0.5, albedo, normal))  # a second frame: the filter kept


class _Failing(_Unshared):
    """A device whose filter fails as a broken GPU's would."""

    def new_filter(self, kind: str) -> Any:
        raise RuntimeError("cudaErrorLaunchFailure (simulated)")


def test_a_gpu_denoiser_that_fails_falls_back_to_the_cpu(caplog: pytest.LogCaptureFixture) -> None:
    from motion.pipeline.render.output.denoise import Denoiser

    color, albedo, normal = _frame()
    broken = Denoiser("llvm_ad_rgb")
    broken.kind, broken._device = "CUDA", _Failing(broken._device)  # as if on a GPU
    with caplog.at_level(logging.WARNING, logger="motion"):
        out = broken(color, albedo, normal)
    assert broken.kind == "CPU" and broken.version["device"] == "CPU"
    assert np.array_equal(out, Denoiser("llvm_ad_rgb")(color, albedo, normal))
    lines = [r.getMessage() for r in caplog.records if "denoise" in r.getMessage()]
    assert len(lines) == 1 and "CUDA device failed" in lines[0] and "simulated" in lines[0]
