"""``python -m torchrl_causal.cli <command> [args]``: the console script ``torchrl-causal``."""

from torchrl_causal.cli import main

if __name__ == "__main__":
    main()
