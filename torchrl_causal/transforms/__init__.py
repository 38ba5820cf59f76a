"""TorchRL transforms that apply causal knowledge to what a policy observes.

:class:`CausalWindowTransform` is the one door through which the adjustment window
computed by :mod:`torchrl_causal.graphs` enters every pipeline: envs and collectors
(online), stored episodes (:meth:`~CausalWindowTransform.encode_trajectories`) and
replay buffers of raw transitions (:class:`EpisodeHistory` and
:class:`EpisodeWindowEncoder`, from
:meth:`~CausalWindowTransform.make_rb_transform_and_sample_unit`).
:class:`RelaxedBinaryAction` presents a binary action to the continuous-control actors.
"""

from torchrl_causal.transforms._layout import FeatureSlice
from torchrl_causal.transforms.actions import RelaxedBinaryAction
from torchrl_causal.transforms.causal_window import CausalWindowTransform, causal_template, imitator_window, step_keys
from torchrl_causal.transforms.replay import EpisodeHistory, EpisodeWindowEncoder

__all__ = [
    "CausalWindowTransform",
    "EpisodeHistory",
    "EpisodeWindowEncoder",
    "FeatureSlice",
    "RelaxedBinaryAction",
    "causal_template",
    "imitator_window",
    "step_keys",
]
