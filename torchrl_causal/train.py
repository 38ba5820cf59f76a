"""``python -m torchrl_causal.train``: the command line :mod:`torchrl_causal.cli.train`, kept at this path."""

from torchrl_causal.cli.train import entry_point, main

__all__ = ["entry_point", "main"]

if __name__ == "__main__":
    entry_point()
