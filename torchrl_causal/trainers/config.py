"""Where the Hydra config tree lives and the resolvers it uses.

The tree sits in ``configs/`` at the repository root, next to the package, so
``python -m torchrl_causal.train`` finds it from any working directory.

Examples:
    >>> from torchrl_causal.trainers.config import compose_config
    >>> cfg = compose_config(["env=rovermaze_u", "algo=sqil", "causal=false", "seed=3"])
    >>> cfg.algo.name, cfg.causal, cfg.seed
    ('sqil', False, 3)
    >>> cfg.run_name
    'rovermaze_u/h1000-cs1.0-k10/sqil/seed3'
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

__all__ = ["CONFIG_DIR", "CONFIG_NAME", "run_label", "register_resolvers", "compose_config"]

CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs"
CONFIG_NAME = "config"


def run_label(algorithm: str, causal: bool, window_matched: bool = False) -> str:
    """The algorithm's name in tables and run directories: ``c_sqil``, ``sqil``, ``expert``.

    Examples:
        >>> run_label("iq_learn", True), run_label("bc", False), run_label("expert", False)
        ('c_iq_learn', 'bc', 'expert')
        >>> run_label("sqil", False, window_matched=True)
        'sqil_wm'
    """
    if algorithm == "expert":
        return "expert"
    if causal and window_matched:
        raise ValueError("window.window_matched=true is a non-causal baseline: use it with causal=false")
    if causal:
        return f"c_{algorithm}"
    return f"{algorithm}_wm" if window_matched else algorithm


def register_resolvers() -> None:
    """Registers ``${run_label:algo,causal,window_matched}`` (idempotent)."""
    if not OmegaConf.has_resolver("run_label"):
        OmegaConf.register_new_resolver("run_label", run_label)


def compose_config(overrides: Sequence[str] = ()) -> DictConfig:
    """Composes ``configs/config.yaml`` with command-line style ``overrides`` (no run).

    Raises:
        FileNotFoundError: if the config tree is not next to the package (a non-editable
            install without the ``configs/`` folder).
    """
    from hydra import compose, initialize_config_dir

    if not (CONFIG_DIR / f"{CONFIG_NAME}.yaml").is_file():
        raise FileNotFoundError(f"Hydra config tree not found at {CONFIG_DIR}")
    register_resolvers()
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        return compose(config_name=CONFIG_NAME, overrides=list(overrides))


register_resolvers()
