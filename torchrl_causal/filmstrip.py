"""``python -m torchrl_causal.filmstrip``: the command line :mod:`torchrl_causal.cli.filmstrip`, kept at this path."""

from torchrl_causal.cli.filmstrip import main

__all__ = ["main"]

if __name__ == "__main__":
    main()
