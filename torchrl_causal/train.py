"""Hydra entry point: ``python -m torchrl_causal.train env=<name> algo=<bc|gail|sqil|iq_learn|expert>
causal=<bool> window.k=<int> seed=<int> [env.horizon=...] [env.confounding_strength=...]``.

The config tree is ``configs/`` next to the package (see ``configs/config.yaml``);
``scale=paper`` selects Appendix E's networks and budgets, ``scale=cpu`` (default) a
2-core budget. Sweeps: ``python -m torchrl_causal.train -m experiment=paper_table``.
A run resumes from ``<run_dir>/checkpoints/last.pt`` and a finished run is skipped.
"""

from __future__ import annotations

import hydra
from omegaconf import DictConfig

from torchrl_causal.trainers import make_trainer
from torchrl_causal.trainers.config import CONFIG_DIR, CONFIG_NAME, register_resolvers

register_resolvers()


@hydra.main(config_path=str(CONFIG_DIR), config_name=CONFIG_NAME, version_base="1.3")
def main(cfg: DictConfig) -> float:
    """Trains, selects and evaluates one run; returns its deploy-regime success rate
    (the value a Hydra sweeper would optimise)."""
    results = make_trainer(cfg).fit()
    for regime, result in results.items():
        print(f"{cfg.run_dir} [{regime}] success {100 * result.success_rate:.1f}% ± {100 * result.success_se:.1f}, "
              f"E[Y] {result.return_mean:.1f} ± {result.return_std:.1f}, episodes {result.n_episodes}")
    return results["deploy"].success_rate


if __name__ == "__main__":
    main()
