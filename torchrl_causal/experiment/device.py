"""Where training runs: ``cfg.device`` resolved once, and checked before anything is written.

Networks, losses, optimisers and sampled replay batches live on the resolved device;
envs always step on the CPU. TorchRL's collectors move observations to the policy and
actions back (``env_device`` / ``policy_device`` / ``storing_device``);
:class:`PolicyOnDevice` does the same for the evaluation loop.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import sys
from collections.abc import Callable
from functools import cache
from typing import Any

import torch
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from torchrl_causal.compat import dynamo_supported
from torchrl_causal.errors import InvalidValueError

__all__ = [
    "BF16_CPU_FLAGS",
    "PRECISIONS",
    "DeviceCheck",
    "PolicyOnDevice",
    "SlurmCheck",
    "bf16_unavailable",
    "compile_unavailable",
    "for_cpu_env",
    "matmul_precision",
    "resolve_device",
    "resolve_precision",
]

CPU = torch.device("cpu")

#: ``algo.precision`` -> the dtype the updates' matmuls run in (``None``: fp32, no autocast).
PRECISIONS: dict[str, torch.dtype | None] = {"fp32": None, "bf16": torch.bfloat16}

#: The ``/proc/cpuinfo`` flags of an x86 CPU with native bf16 matmuls (AVX-512 BF16, AMX).
#: Without one, oneDNN emulates bf16 through fp32 and a bf16 update is slower than fp32's.
BF16_CPU_FLAGS: tuple[str, ...] = ("avx512_bf16", "amx_bf16")


def _available(device: torch.device) -> str | None:
    """Why ``device`` cannot be used on this machine, or ``None`` if it can."""
    if device.type == "cuda":
        if not torch.cuda.is_available():
            build = "a CPU-only build" if torch.version.cuda is None else f"built for CUDA {torch.version.cuda}"
            return f"torch.cuda.is_available() is False (torch {torch.__version__}, {build}; no GPU is visible)"
        if device.index is not None and device.index >= torch.cuda.device_count():
            return f"this machine has {torch.cuda.device_count()} CUDA device(s), so index {device.index} does not exist"
    elif device.type == "mps" and not torch.backends.mps.is_available():
        return "torch.backends.mps.is_available() is False"
    elif device.type not in ("cpu", "cuda", "mps"):
        return "only cpu, cuda, cuda:N, mps and auto are supported"
    return None


def compile_unavailable(device: torch.device) -> str | None:
    """Why ``compile=true`` cannot run on ``device`` here, or ``None`` if it can.

    :func:`torch.compile` needs a Python that dynamo supports, and its CPU backend
    (inductor) builds C++ kernels, so on the CPU it needs a C++ compiler (``$CXX``,
    ``g++``, ``c++`` or ``clang++`` on ``PATH``). ``validate_config`` refuses
    ``compile=true`` with this reason before a run directory exists.
    """
    if not dynamo_supported():
        return f"torch.compile is not supported on Python {sys.version.split()[0]} with torch {torch.__version__}"
    if device.type == "cpu" and not (os.environ.get("CXX") or any(shutil.which(cxx) for cxx in ("g++", "c++", "clang++"))):
        return "torch.compile's CPU backend (inductor) needs a C++ compiler, and none is on PATH (nor in $CXX)"
    return None


@cache
def _cpu_flags() -> frozenset[str]:
    """The CPU's feature flags (``flags`` on x86, ``Features`` on ARM, in ``/proc/cpuinfo``);
    empty where the file does not exist (macOS, Windows)."""
    try:
        with open("/proc/cpuinfo") as handle:
            for line in handle:
                if line.startswith(("flags", "Features")) and ":" in line:
                    return frozenset(line.split(":", 1)[1].split())
    except OSError:
        pass
    return frozenset()


def bf16_unavailable(device: torch.device, cpu_flags: frozenset[str] | None = None) -> str | None:
    """Why ``algo.precision=bf16`` would not run natively on ``device`` here, or ``None``.

    On the CPU it needs :data:`BF16_CPU_FLAGS` (x86) or ``bf16`` (ARM) among the CPU's flags
    (``cpu_flags``, or this machine's ``/proc/cpuinfo``) and oneDNN
    (``torch.backends.mkldnn``); on CUDA, ``torch.cuda.is_bf16_supported()``. Where it is
    missing, bf16 is emulated and slower than fp32, so ``validate_config`` refuses the
    option with this reason instead of running it.

    Examples:
        >>> bf16_unavailable(torch.device("cpu"), cpu_flags=frozenset({"avx512f", "avx512_bf16"})) is None
        True
        >>> bf16_unavailable(torch.device("cpu"), cpu_flags=frozenset({"avx2"}))
        "the CPU has no native bf16 matmuls (neither avx512_bf16 nor amx_bf16 in /proc/cpuinfo's flags)"
    """
    if device.type == "cpu":
        if not torch.backends.mkldnn.is_available():
            return "this torch is built without oneDNN (torch.backends.mkldnn.is_available() is False)"
        flags = _cpu_flags() if cpu_flags is None else cpu_flags
        if not flags & {*BF16_CPU_FLAGS, "bf16"}:
            return f"the CPU has no native bf16 matmuls (neither {' nor '.join(BF16_CPU_FLAGS)} in /proc/cpuinfo's flags)"
        return None
    if device.type == "cuda":
        return None if torch.cuda.is_bf16_supported() else f"{torch.cuda.get_device_name(device)} has no bf16 support"
    return f"bf16 updates run on cpu and cuda, not {device.type}"


def resolve_precision(value: Any) -> str:
    """``algo.precision`` as one of :data:`PRECISIONS`' names: ``None`` (the key's default,
    which runs made before it existed hold as its absence) is ``"fp32"``.

    Examples:
        >>> resolve_precision(None), resolve_precision("bf16")
        ('fp32', 'bf16')
        >>> resolve_precision("fp16")
        Traceback (most recent call last):
        ...
        torchrl_causal.errors.InvalidValueError: precision='fp16' must be one of fp32, bf16
    """
    name = "fp32" if value is None else str(getattr(value, "value", value))  # a config's str enum, or a str
    if name not in PRECISIONS:
        raise InvalidValueError(f"precision={name!r} must be one of {', '.join(PRECISIONS)}")
    return name


def matmul_precision(precision: str, device: torch.device) -> contextlib.AbstractContextManager:
    """The context an update's forward runs in: ``"fp32"``, none; ``"bf16"``,
    :class:`torch.autocast` to bfloat16 on ``device``'s type, so matmuls (and the
    activations between them) run in bf16 while the parameters, their gradients and the
    optimiser state stay fp32. The networks hand their outputs back in their parameters'
    dtype (:class:`~torchrl_causal.modules.ResidualMLP`), so the losses reduce in fp32.

    Examples:
        >>> linear = torch.nn.Linear(4, 2)
        >>> with matmul_precision("bf16", torch.device("cpu")):
        ...     linear(torch.ones(3, 4)).dtype
        torch.bfloat16
        >>> with matmul_precision("fp32", torch.device("cpu")):
        ...     linear(torch.ones(3, 4)).dtype
        torch.float32
    """
    dtype = PRECISIONS[resolve_precision(precision)]
    return contextlib.nullcontext() if dtype is None else torch.autocast(device.type, dtype=dtype)


def resolve_device(spec: str | torch.device) -> torch.device:
    """The device named by ``device=``: ``cpu``, ``cuda``, ``cuda:N``, ``mps`` or ``auto``.

    ``auto`` is the first CUDA device when one is visible, else the CPU.

    Raises:
        ValueError: naming the value, if it is not a device name or the device is not
            available on this machine (``device=cuda`` without a GPU).

    Examples:
        >>> resolve_device("cpu")
        device(type='cpu')
        >>> resolve_device("auto") == (torch.device("cuda", 0) if torch.cuda.is_available() else torch.device("cpu"))
        True
        >>> resolve_device("gpu")
        Traceback (most recent call last):
        ...
        torchrl_causal.errors.InvalidValueError: device='gpu' is not a device name: use cpu, cuda, cuda:N, mps or auto
    """
    if isinstance(spec, str) and spec.strip().lower() == "auto":
        return torch.device("cuda", 0) if torch.cuda.is_available() else CPU
    try:
        device = torch.device(spec)
    except (RuntimeError, TypeError) as err:
        raise InvalidValueError(f"device={spec!r} is not a device name: use cpu, cuda, cuda:N, mps or auto") from err
    problem = _available(device)
    if problem is not None:
        raise InvalidValueError(
            f"device={spec!r} cannot be used here: {problem}. Use device=cpu, or device=auto to take a GPU only when one is present."
        )
    if device.type == "cuda" and device.index is None:
        device = torch.device("cuda", torch.cuda.current_device())
    return device


def _slurm_launcher(config: DictConfig) -> bool:
    """Whether a multirun's launcher sends its jobs to SLURM (``hydra/launcher=slurm``)."""
    return "slurm" in str(OmegaConf.select(config, "hydra.launcher._target_", default="")).lower()


class DeviceCheck(Callback):
    """Hydra callback: a multirun refuses an unavailable ``cfg.device`` before Hydra makes
    the sweep folder.

    A single run needs no callback: it writes nothing before
    :func:`~torchrl_causal.experiment.schema.validate_config`, which checks the device. A
    multirun's launcher creates the sweep folder (``run_root``, for ``multirun.yaml``)
    before any job starts, so ``device=`` is checked here, at ``on_multirun_start``, and
    the process exits with the error (Hydra turns a callback's exceptions into warnings,
    not into a stop). Unless the launcher sends the jobs to other machines (SLURM): a
    login node without a GPU may submit ``device=cuda`` jobs, which each check their own
    node when the job starts.
    """

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        if _slurm_launcher(config):
            return
        try:
            resolve_device(str(config.device))
        except ValueError as err:
            raise SystemExit(f"Error: {err}") from err


class SlurmCheck(Callback):
    """Hydra callback: a multirun through the SLURM launcher (``hydra/launcher=slurm``) is
    refused in one line, before Hydra makes the sweep folder, on a machine without
    ``sbatch``: submitit would fail later with a long traceback.
    """

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        if _slurm_launcher(config) and shutil.which("sbatch") is None:
            raise SystemExit(
                "error: hydra/launcher=slurm submits each job with sbatch, which is not on PATH here: run the sweep "
                "on the cluster's login node, or on this machine with hydra/launcher=processes"
            )


class PolicyOnDevice(TensorDictModuleBase):
    """Runs a policy that lives on ``device`` in an env that steps on the CPU.

    The policy's inputs are moved to ``device`` and its outputs back to the CPU. Collectors do
    this themselves (``policy_device``); this is for loops that call the policy directly, such
    as the evaluation loop.

    Examples:
        >>> from tensordict import TensorDict
        >>> from tensordict.nn import TensorDictModule
        >>> policy = TensorDictModule(torch.nn.Linear(3, 2), in_keys=["observation"], out_keys=["action"])
        >>> td = PolicyOnDevice(policy, "cpu")(TensorDict({"observation": torch.ones(4, 3)}, [4]))
        >>> td["action"].shape, td.device
        (torch.Size([4, 2]), None)
    """

    def __init__(self, policy: TensorDictModuleBase, device: str | torch.device) -> None:
        super().__init__()
        self.policy = policy
        self.device = torch.device(device)
        self.in_keys = list(policy.in_keys)
        self.out_keys = list(policy.out_keys)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        inputs = tensordict.select(*self.in_keys, strict=False).to(self.device)
        outputs = self.policy(inputs).select(*self.out_keys, strict=False)
        return tensordict.update(outputs.to(CPU))


def for_cpu_env(policy: Callable[[TensorDictBase], TensorDictBase]) -> Callable[[TensorDictBase], TensorDictBase]:
    """``policy`` wrapped in :class:`PolicyOnDevice` when its parameters live off the CPU;
    unchanged otherwise (CPU networks, scripted experts without parameters).

    Examples:
        >>> from tensordict.nn import TensorDictModule
        >>> policy = TensorDictModule(torch.nn.Linear(3, 2), in_keys=["observation"], out_keys=["action"])
        >>> for_cpu_env(policy) is policy
        True
    """
    parameter = next(policy.parameters(), None) if isinstance(policy, torch.nn.Module) else None
    if parameter is None or parameter.device == CPU:
        return policy
    return PolicyOnDevice(policy, parameter.device)
