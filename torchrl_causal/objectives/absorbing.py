r"""Absorbing states (Kostrikov et al., "Discriminator-Actor-Critic", ICLR 2019) for imitation losses.

When reaching the goal ends an episode, the value of the goal is zero: every bootstrap
stops there. An imitation reward that is positive on expert-like steps (SQIL's
``r = 1``, IQ-Learn's implicit reward, GAIL's ``-log(1 - D)``) then pays the agent to
stay one step short of the goal for ever rather than enter it. The fix is to let the
episode continue in a fictitious absorbing state ``s_a`` that loops on itself: a
terminal transition ``(s, x, s', terminated)`` becomes ``(s, x, s_a, not terminated)``
and is followed by ``(s_a, x_a, s_a, not terminated)``, for expert and policy data alike,
so that the absorbing state's reward is learned like any other state's.

The replay-buffer format marks these rows with a boolean ``"absorbing"`` flag (and
``("next", "absorbing")``); :func:`add_absorbing_transitions` converts a flat batch of
transitions, and :class:`AbsorbingStateValue` wraps a Q-network or a discriminator so
that every row flagged absorbing gets one learned scalar instead of the network's
output (every action in the absorbing state leads back to it, so its value does not
depend on the action).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from tensordict.utils import NestedKey
from torch import nn

__all__ = ["ABSORBING_KEY", "AbsorbingStateValue", "add_absorbing_transitions"]

#: The replay-buffer key of the absorbing-state flag (``("next", ABSORBING_KEY)`` for the next state).
ABSORBING_KEY = "absorbing"


def add_absorbing_transitions(
    transitions: TensorDictBase,
    *,
    absorbing_key: NestedKey = ABSORBING_KEY,
    zeroed_keys: Sequence[NestedKey] = ("observation", "action", ("next", "observation")),
    terminated_key: NestedKey = ("next", "terminated"),
    done_key: NestedKey = ("next", "done"),
) -> TensorDictBase:
    """Flat transitions with an absorbing transition appended for every terminal one.

    Every terminal transition (``terminated`` True) is rewritten to lead into the
    absorbing state: ``("next", absorbing_key)`` True, ``terminated`` and ``done`` False,
    its next observation zeroed. For each of them one absorbing transition is appended:
    both flags True, not terminated, not done, the ``zeroed_keys`` (observation, action,
    next observation) set to zero, every other entry (the ``"expert"`` flag included)
    copied from the terminal transition. Non-terminal rows get both flags False and
    are otherwise unchanged; a time-limit truncation (done but not terminated) stays
    as it is. The input is not modified.

    Args:
        transitions (TensorDictBase): one-dimensional batch of transitions.

    Keyword Args:
        absorbing_key (NestedKey, optional): the flag written at the root and under
            ``"next"``. Defaults to ``"absorbing"``.
        zeroed_keys (sequence of NestedKey, optional): entries set to zero in the
            absorbing state (those that are present). Defaults to the observation, the
            action and the next observation.
        terminated_key, done_key (NestedKey, optional): the episode-end flags.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> terminated = torch.tensor([[False], [True], [False]])
        >>> batch = TensorDict({
        ...     "observation": torch.tensor([[1.0], [2.0], [3.0]]),
        ...     "action": torch.ones(3, 1),
        ...     "expert": torch.ones(3, 1, dtype=torch.bool),
        ...     "next": {"observation": torch.tensor([[2.0], [9.0], [4.0]]),
        ...              "terminated": terminated, "done": terminated.clone()},
        ... }, [3])
        >>> out = add_absorbing_transitions(batch)
        >>> out["observation"].squeeze(-1).tolist(), out["next", "observation"].squeeze(-1).tolist()
        ([1.0, 2.0, 3.0, 0.0], [2.0, 0.0, 4.0, 0.0])
        >>> out["absorbing"].squeeze(-1).tolist(), out["next", "absorbing"].squeeze(-1).tolist()
        ([False, False, False, True], [False, True, False, True])
        >>> bool(out["next", "terminated"].any()), out["expert"].all().item()
        (False, True)
    """
    if transitions.batch_dims != 1:
        raise ValueError(
            f"add_absorbing_transitions expects a flat batch of transitions, got batch size {tuple(transitions.batch_size)}."
        )
    terminated = transitions.get(terminated_key, None)
    if terminated is None:
        raise KeyError(f"transitions need the terminal flag {terminated_key!r} to place absorbing states.")
    terminated = terminated.reshape(transitions.shape[0], -1).any(-1)
    out = transitions.clone()
    out.set(absorbing_key, torch.zeros(*out.shape, 1, dtype=torch.bool))
    out.set(("next", absorbing_key), terminated.unsqueeze(-1).clone())
    absorbing = out[terminated].clone()
    if done_key in out.keys(True):
        out.get(done_key)[terminated] = False
    out.get(terminated_key)[terminated] = False
    if ("next", "observation") in zeroed_keys and ("next", "observation") in out.keys(True):
        out.get(("next", "observation"))[terminated] = 0
    for key in zeroed_keys:
        if key in absorbing.keys(True):
            absorbing.get(key).zero_()
    absorbing.set(absorbing_key, torch.ones(*absorbing.shape, 1, dtype=torch.bool))
    absorbing.set(("next", absorbing_key), torch.ones(*absorbing.shape, 1, dtype=torch.bool))
    absorbing.get(terminated_key).zero_()
    if done_key in absorbing.keys(True):
        absorbing.get(done_key).zero_()
    return torch.cat([out, absorbing], dim=0)


class AbsorbingStateValue(TensorDictModuleBase):
    """Replaces a network's output by one learned scalar on rows flagged absorbing.

    Wraps a Q-network or a discriminator (a module with one output key). The network
    runs on every row; where ``absorbing_key`` is True its output is replaced by the
    parameter :attr:`absorbing_value` (initialised to ``init``), so the gradient of
    those rows reaches only that parameter. Passed to a loss that copies its critics
    (SAC's twin critics), each copy gets its own absorbing value and target.

    Args:
        network (TensorDictModuleBase): the wrapped module, with a single out key.

    Keyword Args:
        absorbing_key (NestedKey, optional): the boolean flag read from the input.
            Defaults to ``"absorbing"``.
        init (float, optional): initial absorbing value. Defaults to ``0.0``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import Bounded
        >>> from torchrl_causal.modules import make_qvalue_network
        >>> q = AbsorbingStateValue(make_qvalue_network(3, Bounded(-1.0, 1.0, shape=(2,)), hidden=8), init=5.0)
        >>> td = TensorDict({"observation": torch.randn(2, 3), "action": torch.zeros(2, 2),
        ...                  "absorbing": torch.tensor([[False], [True]])}, [2])
        >>> q(td)["state_action_value"][1].item()
        5.0
    """

    def __init__(self, network: TensorDictModuleBase, *, absorbing_key: NestedKey = ABSORBING_KEY,
                 init: float = 0.0) -> None:
        super().__init__()
        if len(network.out_keys) != 1:
            raise ValueError(f"AbsorbingStateValue wraps a module with one out key, got {network.out_keys}.")
        self.network = network
        self.absorbing_key = absorbing_key
        self.absorbing_value = nn.Parameter(torch.tensor(float(init)))
        self.in_keys = [*network.in_keys, absorbing_key]
        self.out_keys = list(network.out_keys)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        flag = tensordict.get(self.absorbing_key, None)
        if flag is None:
            raise KeyError(
                f"{type(self).__name__} needs the boolean absorbing flag {self.absorbing_key!r}; "
                f"found keys {list(tensordict.keys(True, True))}."
            )
        tensordict = self.network(tensordict)
        value = tensordict.get(self.out_keys[0])
        tensordict.set(self.out_keys[0], torch.where(flag, self.absorbing_value.to(value.dtype), value))
        return tensordict
