"""``python -m torchrl_causal.evaluate``: the command line :mod:`torchrl_causal.cli.evaluate`, kept at this path."""

from torchrl_causal.cli.evaluate import main

__all__ = ["main"]

if __name__ == "__main__":
    main()
