"""Old path of :mod:`torchrl_causal.experts.locomotion_ppo`: ``python -m torchrl_causal.envs.locomotion_ppo
--export-from ...``, as the archived results quote it, runs the same command line; nothing in the package imports it."""

from torchrl_causal.experts import locomotion_ppo as moved

__all__ = moved.__all__


def __getattr__(name: str) -> object:
    return getattr(moved, name)


if __name__ == "__main__":
    moved.main()
