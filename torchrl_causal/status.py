"""``python -m torchrl_causal.status``: the command line :mod:`torchrl_causal.cli.status`, kept at this path."""

from torchrl_causal.cli.status import main

__all__ = ["main"]

if __name__ == "__main__":
    main()
