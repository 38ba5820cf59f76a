"""A TorchRL collector that checkpoints the episodes in flight.

TorchRL's :class:`~torchrl.collectors.Collector` saves its transforms' state and frame
counters, and starts new episodes when loaded: the state of an arbitrary env is not
serialisable. The confounded envs' state is (their module extra state: generator,
bodies, gusts), and so are the lag buffers of
:class:`~torchrl_causal.transforms.CausalWindowTransform`; with them and the collector's
carrier (the step about to be acted on) a loaded collector continues every episode
exactly where it stood, which is what makes a resumed run equal an uninterrupted one.
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Any

from torchrl.collectors import Collector
from torchrl.envs import TransformedEnv

from torchrl_causal.compat import collector_carrier

__all__ = ["ResumableCollector"]


class ResumableCollector(Collector):
    """:class:`~torchrl.collectors.Collector` over a :class:`~torchrl.envs.TransformedEnv`
    whose state dict also holds the base env's state and the carrier.

    Examples:
        >>> import torch
        >>> from tensordict.nn import TensorDictModule
        >>> from torchrl.envs import TransformedEnv
        >>> from torchrl_causal.envs import RoverMazeEnv
        >>> policy = TensorDictModule(torch.nn.Linear(2, 2), in_keys=["P"], out_keys=["action"])
        >>> make = lambda: ResumableCollector(TransformedEnv(RoverMazeEnv(maze="u", batch_size=(2,), seed=0)),
        ...                                   policy, frames_per_batch=8, total_frames=-1,
        ...                                   auto_register_policy_transforms=False)
        >>> collector = make()
        >>> batches = iter(collector)
        >>> _ = next(batches)
        >>> saved = collector.state_dict()  # mid-episode: 4 steps into the first episodes
        >>> expected = next(batches)["next", "P"]
        >>> restored = make()
        >>> restored.load_state_dict(saved)
        >>> torch.equal(next(iter(restored))["next", "P"], expected)
        True
    """

    env: TransformedEnv

    def state_dict(self) -> OrderedDict:
        state = super().state_dict()
        state["base_env_state_dict"] = self.env.base_env.state_dict()
        state["carrier"] = collector_carrier(self).to_dict()
        return state

    def load_state_dict(self, state_dict: OrderedDict, **kwargs: Any) -> None:
        super().load_state_dict(state_dict, **kwargs)
        self.env.base_env.load_state_dict(state_dict["base_env_state_dict"])
        collector_carrier(self).update_(state_dict["carrier"])
