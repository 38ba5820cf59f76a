"""Old path of :mod:`torchrl_causal.experts.policies`, kept for archived configs
(``_target_: torchrl_causal.envs.experts.RouteChoiceExpert``); nothing in the package imports it."""

from torchrl_causal.experts import policies as moved

__all__ = moved.__all__


def __getattr__(name: str) -> object:
    return getattr(moved, name)
