"""``python -m torchrl_causal.demo``: the command line :mod:`torchrl_causal.cli.demo`, kept at this path."""

from torchrl_causal.cli.demo import main

__all__ = ["main"]

if __name__ == "__main__":
    main()
