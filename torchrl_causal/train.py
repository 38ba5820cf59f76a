"""``python -m torchrl_causal.train``: the command line :mod:`torchrl_causal.cli.train`, kept at this path."""

from torchrl_causal.cli.train import main

__all__ = ["main"]

if __name__ == "__main__":
    main()
