"""``python -m torchrl_causal.report``: the command line :mod:`torchrl_causal.cli.report`, kept at this path."""

from torchrl_causal.cli.report import main

__all__ = ["main"]

if __name__ == "__main__":
    main()
