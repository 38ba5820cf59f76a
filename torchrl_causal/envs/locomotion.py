"""Old path of :mod:`torchrl_causal.experts.locomotion`: ``python -m torchrl_causal.envs.locomotion ...``,
as the archived results quote it, runs the same command line; nothing in the package imports it."""

from torchrl_causal.experts import locomotion as moved

__all__ = moved.__all__


def __getattr__(name: str) -> object:
    return getattr(moved, name)


if __name__ == "__main__":
    moved.main()
