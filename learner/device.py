"""Where the learner computes: the torch device, its threads, its convolution precision."""

from __future__ import annotations

import torch

from learner.machine import default_threads


def resolve_device(name: str) -> torch.device:
    """`auto` is CUDA when available, else the CPU; an explicit CUDA device must exist."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    device = torch.device(name)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device {name!r} asked for, but torch sees no CUDA device; use 'auto'")
    return device


def configure_threads(threads: int) -> int:
    """Set torch's CPU threads for this process (0: half the cores, 1 to 4) and return it.

    Half, because the simulator, the server and other workers need the rest: when torch's
    threads outnumber the free cores, every parallel operation waits for a descheduled
    thread, and on a busy 2-core machine a 2-thread run measured 8x slower than a 1-thread
    one (an idle one is 1.8x faster with 2). Beyond 4 the small convolutions gain little.
    """
    if threads == 0:
        threads = default_threads()
    if torch.get_num_threads() != threads:
        torch.set_num_threads(threads)
    return threads


def bf16_native(device: torch.device) -> bool:
    """Whether bfloat16 convolutions run natively (not emulated) on this device."""
    if device.type == "cuda":
        return torch.cuda.is_bf16_supported()
    if device.type == "cpu":
        cpu = torch.cpu
        checks = ("_is_avx512_bf16_supported", "_is_amx_tile_supported")
        return any(getattr(cpu, check, lambda: False)() for check in checks)
    return False


def conv_dtype(precision: str, device: torch.device) -> torch.dtype:
    """The dtype of the fast update's convolutions for a config's `precision`."""
    if precision == "fp32" or (precision == "auto" and not bf16_native(device)):
        return torch.float32
    return torch.bfloat16
