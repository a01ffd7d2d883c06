"""What this machine can compute, read without torch (the web process pins a run's numerics
when it creates the session, and loads no torch): the CPU's kind and bfloat16 support, the
learner's compiled convolutions, a CUDA device, the cores and the memory. `learner.device`
asks torch the same questions where torch is loaded; a test checks the two agree here."""

from __future__ import annotations

import os
import platform
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, cast

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
"""The network's layers a run pinned here computes with a compiled variant (the rest in
PyTorch); the first is always among them."""
CONV_KERNEL_LAYER_SETS = (frozenset({1}), frozenset({1, 2, 3}))
"""The layer sets this code computes a pinned run's convolutions with: the first alone (a
variant's bare name, `avx2`, pinned when the first layer alone had a kernel) and all three
(`avx2:1-3`). A run pinned to another set would not take the same steps here."""
CONV_KERNEL_VARIANTS: dict[str, tuple[set[str], str]] = {
    "avx512bf16": ({"avx512f", "avx512bw", "avx512vl", "avx512vbmi", "avx512_bf16", "fma"}, "bf16"),
    "avx2": ({"avx2", "fma"}, "fp32"),
}
"""The compiled convolutions' instruction-set variants (`learner.conv_kernel`): the CPU
flags each needs, the convolution precision it computes in. A run's `config.conv_kernel`
names one with the layers it computes (`conv_kernel_parts`)."""


def conv_kernel_parts(name: str) -> tuple[str, frozenset[int]]:
    """A pinned `config.conv_kernel`'s instruction-set variant and the layers it computes
    with it: `avx2:1-3` is `avx2` for layers 1 to 3, `avx2:1,3` for layers 1 and 3; a bare
    variant, `avx2`, the first layer alone (what it computed when it was pinned)."""
    variant, _, label = name.partition(":")
    if not label:
        return variant, frozenset({1})
    layers: set[int] = set()
    for part in label.split(","):
        first, _, last = part.partition("-")
        layers.update(range(int(first), int(last or first) + 1))
    return variant, frozenset(layers)


def conv_kernel_name(variant: str, layers: tuple[int, ...] | frozenset[int]) -> ConvKernel:
    """The `config.conv_kernel` that pins `variant` for `layers` (`conv_kernel_parts`'
    inverse): the bare variant for the first layer alone, else `variant:first-last`."""
    ordered = sorted(layers)
    if ordered == [1]:
        return cast("ConvKernel", variant)
    if ordered == list(range(ordered[0], ordered[-1] + 1)):
        label = f"{ordered[0]}-{ordered[-1]}"
    else:
        label = ",".join(str(layer) for layer in ordered)
    return cast("ConvKernel", f"{variant}:{label}")


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


def conv_kernel_runs(name: str) -> bool:
    """The compiled convolutions' variant `name` (`avx2`, `avx2:1-3`: its instruction set
    decides) is built here and this CPU has its instructions."""
    variant, _ = conv_kernel_parts(name)
    needs, _ = CONV_KERNEL_VARIANTS[variant]
    built = all(
        (CONV_KERNEL_BUILD / f"{library}_{variant}.so").exists()
        for library in CONV_KERNEL_LIBRARIES
    )
    return needs <= cpu_flags() and built


def conv_kernel_layers_computed(name: str) -> bool:
    """This code computes the layers the pinned `name` names (`CONV_KERNEL_LAYER_SETS`)."""
    return conv_kernel_parts(name)[1] in CONV_KERNEL_LAYER_SETS


def conv_kernel_for(precision: str) -> ConvKernel:
    """The compiled convolutions a run in `precision` (`bf16`, `fp32`) takes here when it
    leaves the choice open, named with the layers they compute (`CONV_KERNEL_LAYERS`):
    the variant that runs here where the switch (`CONV_KERNEL_SWITCH`) is on, else `none`
    (the PyTorch update)."""
    if os.environ.get(CONV_KERNEL_SWITCH, "off") != "on":
        return "none"
    for variant, (_, variant_precision) in CONV_KERNEL_VARIANTS.items():
        if variant_precision == precision and conv_kernel_runs(variant):
            return conv_kernel_name(variant, CONV_KERNEL_LAYERS)
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
