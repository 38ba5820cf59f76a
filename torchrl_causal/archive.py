"""``python -m torchrl_causal.archive``: the command line :mod:`torchrl_causal.cli.archive`, kept at this path."""

from torchrl_causal.cli.archive import main

__all__ = ["main"]

if __name__ == "__main__":
    main()
