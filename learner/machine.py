"""What this machine can compute, read without torch (the web process pins a run's numerics
when it creates the session, and loads no torch): the CPU's kind and bfloat16 support, the
learner's compiled convolutions, a CUDA device, the cores and the memory. `learner.device`
asks torch the same questions where torch is loaded; a test checks the two agree here."""

from __future__ import annotations

import os
import platform
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from learner.config import ConvKernel

BF16_FLAGS = ("avx512_bf16", "amx_bf16")
"""CPU flags with which bfloat16 convolutions run natively (oneDNN's AVX-512 BF16 or AMX)."""
CONV_KERNEL_SWITCH = "IDEEPRL_CONV_KERNEL"
"""The environment variable with which a run left to choose (`config.conv_kernel` `auto`)
takes the compiled convolutions (`on`); anything else: off."""
CONV_KERNEL_BUILD = Path(__file__).parent / "kernels" / "build"
"""Where `make kernels` puts the compiled convolutions' libraries (`LIBRARIES`)."""
CONV_KERNEL_LIBRARIES = ("libconv1", "libconv23")
"""The libraries a variant needs, `<name>_<variant>.so`: the first layer, the second and
third."""
CONV_KERNEL_LAYERS = (1, 2, 3)
"""The network's layers a run with a compiled variant computes with it (the rest in
PyTorch); the first is always among them."""
CONV_KERNEL_VARIANTS: dict[ConvKernel, tuple[set[str], str]] = {
    "avx512bf16": ({"avx512f", "avx512bw", "avx512vl", "avx512vbmi", "avx512_bf16", "fma"}, "bf16"),
    "avx2": ({"avx2", "fma"}, "fp32"),
}
"""The compiled convolutions' variants (`learner.conv_kernel`): the CPU flags each needs, the
convolution precision it computes in."""


@cache
def cpu_flags() -> frozenset[str]:
    """The CPU's feature flags (/proc/cpuinfo; empty where there is none)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return frozenset()
    for line in text.splitlines():
        if line.startswith("flags"):
            return frozenset(line.partition(":")[2].split())
    return frozenset()


@cache
def cpu_model() -> str:
    """The CPU's model name ('AMD EPYC', 'Intel(R) Xeon(R) ...')."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return " ".join(line.partition(":")[2].split())
    except OSError:
        pass
    return platform.processor() or platform.machine()


def cpu_kind() -> str:
    """The CPU kind as this project names it: model, and which of AVX-512, AVX-512 BF16 and
    AMX it has (the kinds change between machines and decide the numerics)."""
    flags = cpu_flags()
    has = [
        name
        for name, flag in (
            ("AVX-512", "avx512f"),
            ("AVX-512 BF16", "avx512_bf16"),
            ("AMX", "amx_bf16"),
        )
        if flag in flags
    ]
    return f"{cpu_model()} ({', '.join(has) if has else 'no AVX-512'})"


def bf16_native_cpu() -> bool:
    """bfloat16 convolutions run natively on this CPU."""
    return any(flag in cpu_flags() for flag in BF16_FLAGS)


def conv_kernel_runs(variant: ConvKernel) -> bool:
    """The compiled convolutions' `variant` is built here and this CPU has its instructions."""
    needs, _ = CONV_KERNEL_VARIANTS[variant]
    built = all(
        (CONV_KERNEL_BUILD / f"{name}_{variant}.so").exists() for name in CONV_KERNEL_LIBRARIES
    )
    return needs <= cpu_flags() and built


def conv_kernel_for(precision: str) -> ConvKernel:
    """The compiled convolutions' variant a run in `precision` (`bf16`, `fp32`) takes here
    when it leaves the choice open: the one that runs here where the switch
    (`CONV_KERNEL_SWITCH`) is on, else `none` (the PyTorch update)."""
    if os.environ.get(CONV_KERNEL_SWITCH, "off") != "on":
        return "none"
    for variant, (_, variant_precision) in CONV_KERNEL_VARIANTS.items():
        if variant_precision == precision and conv_kernel_runs(variant):
            return variant
    return "none"


def cuda_present() -> bool:
    """An NVIDIA GPU with its driver loaded (what torch would use); CUDA_VISIBLE_DEVICES=""
    hides it, as it hides it from torch."""
    if os.environ.get("CUDA_VISIBLE_DEVICES", None) == "":
        return False
    gpus = Path("/proc/driver/nvidia/gpus")
    return gpus.is_dir() and any(gpus.iterdir())


def usable_cores() -> int:
    """The cores this process may run on."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def total_memory() -> int:
    """This machine's memory in bytes."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return 0


def default_threads() -> int:
    """Torch threads when a run leaves them open: half the cores, 1 to 4 (the simulator, the
    server and other workers need the rest; `learner.device.configure_threads`)."""
    return max(1, min(4, usable_cores() // 2))
