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
transitions, and :class:`AbsorbingIndicator` feeds the flag to a Q-network or a
discriminator as one more input feature.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from tensordict.utils import NestedKey

from torchrl_causal.errors import InvalidValueError, UnknownKeyError

__all__ = ["ABSORBING_KEY", "AbsorbingIndicator", "add_absorbing_transitions"]

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
        raise InvalidValueError(
            f"add_absorbing_transitions expects a flat batch of transitions, got batch size {tuple(transitions.batch_size)}."
        )
    terminated = transitions.get(terminated_key, None)
    if terminated is None:
        raise UnknownKeyError(f"transitions need the terminal flag {terminated_key!r} to place absorbing states.")
    terminated = terminated.reshape(transitions.shape[0], -1).any(-1)
    out = transitions.clone()
    out.set(absorbing_key, torch.zeros(*out.shape, 1, dtype=torch.bool, device=terminated.device))
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
    absorbing.set(absorbing_key, torch.ones(*absorbing.shape, 1, dtype=torch.bool, device=terminated.device))
    absorbing.set(("next", absorbing_key), torch.ones(*absorbing.shape, 1, dtype=torch.bool, device=terminated.device))
    absorbing.get(terminated_key).zero_()
    if done_key in absorbing.keys(True):
        absorbing.get(done_key).zero_()
    return torch.cat([out, absorbing], dim=0)


class AbsorbingIndicator(TensorDictModuleBase):
    """Feeds a network its observation with the absorbing flag appended as one more feature.

    Wraps a Q-network or a discriminator built for ``observation_dim + 1`` input
    features: the flag (0 or 1) is concatenated to ``observation_key`` before the
    network runs, as in Kostrikov et al.'s absorbing-state indicator, so the network
    learns the absorbing state's value with all of its parameters (the absorbing
    state's observation itself is all zeros). Passed to a loss that copies its critics
    (SAC's twin critics), every copy reads the flag.

    Args:
        network (TensorDictModuleBase): the wrapped module, reading ``observation_key``.

    Keyword Args:
        observation_key (NestedKey, optional): the input the flag is appended to.
            Defaults to ``"observation"``.
        absorbing_key (NestedKey, optional): the boolean flag. Defaults to ``"absorbing"``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import Bounded
        >>> from torchrl_causal.modules import make_qvalue_network
        >>> q = AbsorbingIndicator(make_qvalue_network(3 + 1, Bounded(-1.0, 1.0, shape=(2,)), hidden=8))
        >>> td = TensorDict({"observation": torch.zeros(2, 3), "action": torch.zeros(2, 2),
        ...                  "absorbing": torch.tensor([[False], [True]])}, [2])
        >>> values = q(td)["state_action_value"]
        >>> values.shape, bool(values[0] != values[1]), td["observation"].shape
        (torch.Size([2, 1]), True, torch.Size([2, 3]))
    """

    def __init__(
        self, network: TensorDictModuleBase, *, observation_key: NestedKey = "observation", absorbing_key: NestedKey = ABSORBING_KEY
    ) -> None:
        super().__init__()
        if observation_key not in network.in_keys:
            raise UnknownKeyError(
                f"AbsorbingIndicator appends the flag to {observation_key!r}, which the network does not read (in_keys {network.in_keys})."
            )
        self.network = network
        self.observation_key = observation_key
        self.absorbing_key = absorbing_key
        self.in_keys = [*network.in_keys, absorbing_key]
        self.out_keys = list(network.out_keys)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        flag = tensordict.get(self.absorbing_key, None)
        if flag is None:
            raise UnknownKeyError(
                f"{type(self).__name__} needs the boolean absorbing flag {self.absorbing_key!r}; "
                f"found keys {list(tensordict.keys(True, True))}."
            )
        observation = tensordict.get(self.observation_key)
        inputs = tensordict.select(*self.network.in_keys)
        inputs.set(self.observation_key, torch.cat([observation, flag.to(observation.dtype)], dim=-1))
        outputs = self.network(inputs)
        for key in self.out_keys:
            tensordict.set(key, outputs.get(key))
        return tensordict
