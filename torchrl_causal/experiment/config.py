"""Where the Hydra config tree lives, its resolvers and schemas, and composing it.

The tree is package data, ``torchrl_causal/conf/``, so ``python -m torchrl_causal.train``
finds it from any working directory, in a checkout or an installed wheel. Its groups are
typed by the structured configs of :mod:`torchrl_causal.experiment.schema`.

Examples:
    >>> from torchrl_causal.experiment.config import compose_config
    >>> cfg = compose_config(["env=rovermaze_u", "algo=sqil", "causal=false", "seed=3"])
    >>> cfg.algo.name, cfg.causal, cfg.seed
    ('sqil', False, 3)
    >>> cfg.run_name
    'rovermaze_u/h1000-cs1.0-k10/sqil/seed3'
    >>> compose_config(["seed=abc"])  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    hydra.errors.ConfigCompositionException: Error merging override seed=abc
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from torchrl_causal.algorithms import ROW_SETS, row_names
from torchrl_causal.errors import InvalidValueError, MissingFileError
from torchrl_causal.experiment.run_directory import run_label
from torchrl_causal.experiment.schema import register_configs

__all__ = ["CONFIG_DIR", "CONFIG_MODULE", "CONFIG_NAME", "CONFIG_PATH", "register_resolvers", "compose_config"]

#: The package that holds the tree, and Hydra's search path for it (works from a wheel).
CONFIG_MODULE = "torchrl_causal.conf"
CONFIG_PATH = f"pkg://{CONFIG_MODULE}"
#: The same tree as a folder, for reading its files (the groups' options, say).
CONFIG_DIR = Path(__file__).resolve().parents[1] / "conf"
CONFIG_NAME = "config"


def stable_id(text: str) -> str:
    """A 16-character id that depends on ``text`` only (``${stable_id:${run_dir}}``: the W&B
    run of a run directory, the same across resumes and requeues).

    Examples:
        >>> stable_id("runs/route_choice/seed0") == stable_id("runs/route_choice/seed0") != stable_id("runs/x")
        True
        >>> len(stable_id("runs/x"))
        16
    """
    return hashlib.sha1(str(text).encode()).hexdigest()[:16]


def product(*factors: int) -> int:
    """``${product:${threads},${collector_workers}}``: the cores a run uses.

    Examples:
        >>> product(2, 3)
        6
    """
    return math.prod(int(factor) for factor in factors)


def rows(which: str) -> str:
    """``${rows:table1}``, ``${rows:all}``: a sweep's row list, from :mod:`torchrl_causal.algorithms`.

    Examples:
        >>> rows("table1")
        'expert,c_bc,c_gail,c_sqil,c_iq_learn,bc,gail,sqil,iq_learn'
    """
    if which not in ROW_SETS:
        raise InvalidValueError(f"${{rows:{which}}}: no such row set; use one of {sorted(ROW_SETS)}")
    return row_names(ROW_SETS[which])


def gpus_for(device: str) -> int | None:
    """``${gpus_for:${device}}``: the GPUs a SLURM job of a run on ``device`` asks for: one for
    CUDA, none (``None``: no ``--gpus-per-node`` line) for the CPU or any other device.

    Examples:
        >>> gpus_for("cuda"), gpus_for("cuda:1"), gpus_for("cpu"), gpus_for("auto")
        (1, 1, None, None)
    """
    return 1 if str(device).split(":")[0] == "cuda" else None


def shift_tag(shift: str | None) -> str:
    """``${shift_tag:${env.shift}}``: what run and demonstration paths add for a deployment
    shift other than the default rotation, so that its runs and demonstrations (collected in
    another training regime) never share a folder with the rotation's.

    Examples:
        >>> shift_tag(None), shift_tag("rotation"), shift_tag("prior")
        ('', '', '-prior')
    """
    return "" if shift in (None, "rotation") else f"-{shift}"


_RESOLVERS: dict[str, Callable[..., Any]] = {
    "run_label": run_label,
    "stable_id": stable_id,
    "product": product,
    "rows": rows,
    "gpus_for": gpus_for,
    "shift_tag": shift_tag,
}


def register_resolvers() -> None:
    """Registers ``${run_label:algo,causal,window_matched,drop}``, ``${stable_id:...}``,
    ``${product:...}``, ``${rows:...}``, ``${gpus_for:...}``, ``${shift_tag:...}`` and the schemas (idempotent)."""
    for name, resolver in _RESOLVERS.items():
        if not OmegaConf.has_resolver(name):
            OmegaConf.register_new_resolver(name, resolver)
    register_configs()


def compose_config(overrides: Sequence[str] = ()) -> DictConfig:
    """Composes ``conf/config.yaml`` with command-line style ``overrides`` (no run).

    Types are checked here; ranges by :func:`~torchrl_causal.experiment.schema.validate_config`.

    Raises:
        FileNotFoundError: if the package was installed without its ``conf/`` data.
        hydra.errors.ConfigCompositionException: a value of the wrong type, an unknown
            key or an unknown group option, naming it.
    """
    from hydra import compose, initialize_config_module

    if not (CONFIG_DIR / f"{CONFIG_NAME}.yaml").is_file():
        raise MissingFileError(f"Hydra config tree not found at {CONFIG_DIR}: the package was installed without its data")
    register_resolvers()
    with initialize_config_module(config_module=CONFIG_MODULE, version_base="1.3"):
        return compose(config_name=CONFIG_NAME, overrides=list(overrides))


register_resolvers()
