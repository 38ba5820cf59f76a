"""``python -m torchrl_causal.strength_ablation``: the command line :mod:`torchrl_causal.cli.strength_ablation`, kept at this path."""

from torchrl_causal.cli.strength_ablation import main

__all__ = ["main"]

if __name__ == "__main__":
    main()
