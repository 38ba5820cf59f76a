"""TorchRL transforms that apply causal knowledge to what a policy observes.

:class:`CausalWindowTransform` is the one door through which the adjustment window
computed by :mod:`torchrl_causal.graphs` enters every pipeline (envs, collectors,
replay buffers, offline demonstrations).
"""

from torchrl_causal.transforms._layout import FeatureSlice
from torchrl_causal.transforms.causal_window import CausalWindowTransform, causal_template
from torchrl_causal.transforms.replay import EpisodeHistory, EpisodeWindowEncoder

__all__ = ["CausalWindowTransform", "EpisodeHistory", "EpisodeWindowEncoder", "FeatureSlice", "causal_template"]
