"""The paper's Confounded Route Choice example (Appendix, Example "Confounded Route Choice").

A single-stage SCM with binary variables: the goal side ``Z ~ Bern(1/2)``, the expert's
orientation ``O ~ Bern(2/3)`` (latent to the imitator), the wind ``U ~ Bern(p)`` (the
confounder, unobserved by everyone), the compass ``W = O xor U`` (a collider), the action
``X`` and the outcome ``Y``. The route is ``A = X xor Z``: the exposed route ``A = 0``
succeeds with probability ``1 - U``, the sheltered route ``A = 1`` with probability 3/4.
The expert takes the route it faces, ``X = Z xor O``.

The wind probability is ``1/4`` in the train regime and ``1/4 + strength / 2`` when
deployed (``3/4`` at full strength, the paper's ``p_te``). :func:`route_choice_value`
computes ``E[Y | do(pi)]`` exactly by enumerating the 8 exogenous configurations.
"""

from __future__ import annotations

from collections.abc import Callable
from fractions import Fraction
from functools import cache
from itertools import product
from numbers import Rational
from typing import TYPE_CHECKING

import torch
from torchrl.data import Binary

from torchrl_causal.envs.base import ConfoundedEnv
from torchrl_causal.errors import InvalidValueError

if TYPE_CHECKING:
    from torchrl_causal.graphs import TimeSliceTemplate

__all__ = ["RouteChoiceEnv", "route_choice_value", "TRAIN_WIND", "DEPLOY_WIND"]

GOAL_SIDE_PROBABILITY = Fraction(1, 2)  # P(Z = 1)
ORIENTATION_PROBABILITY = Fraction(2, 3)  # P(O = 1)
SHELTERED_SUCCESS = Fraction(3, 4)  # P(Y = 1 | A = 1, u) for every u
TRAIN_WIND = Fraction(1, 4)  # p_tr
DEPLOY_WIND = Fraction(3, 4)  # p_te, reached at confounding_strength = 1

#: A probability given exactly (an int or a Fraction) or as a float (type checkers take an
#: int for a float; ``numbers.Real`` is not a type they check).
Probability = float | Fraction
RouteChoicePolicy = Callable[[int, int, int], Probability]


def _success_probability(route: int, wind: int) -> Fraction:
    """P(Y = 1 | A = route, U = wind): exposed succeeds only when calm, sheltered 3/4."""
    return SHELTERED_SUCCESS if route == 1 else Fraction(1 - wind)


def _bernoulli(p: Fraction, value: int) -> Fraction:
    return p if value == 1 else 1 - p


def _as_fraction(value: Probability) -> Fraction:
    # Floats such as 3/5 are not exact in binary; a bounded denominator recovers the
    # intended rational while leaving exact inputs (ints, Fractions) untouched.
    if isinstance(value, Rational):
        return Fraction(value)
    return Fraction(float(value)).limit_denominator(10**6)


def route_choice_value(policy: RouteChoicePolicy, wind_probability: Probability) -> Fraction:
    """``E[Y | do(policy)]`` by exhaustive enumeration over ``(Z, O, U)``.

    Args:
        policy: ``policy(z, o, w)`` returns ``P(X = 1)`` (any real in [0, 1]; floats are
            read as the nearest fraction with denominator at most 10**6). A policy that
            ignores ``o`` is one the imitator can run.
        wind_probability: ``P(U = 1)``.

    Examples:
        >>> expert = lambda z, o, w: float(z ^ o)
        >>> route_choice_value(expert, Fraction(1, 4)), route_choice_value(expert, Fraction(3, 4))
        (Fraction(3, 4), Fraction(7, 12))
        >>> route_choice_value(lambda z, o, w: float(z ^ w), Fraction(3, 4))  # follows the compass
        Fraction(19, 48)
    """
    wind = _as_fraction(wind_probability)
    if not 0 <= wind <= 1:
        raise InvalidValueError(f"wind_probability must lie in [0, 1], got {wind_probability!r}")
    value = Fraction(0)
    for z, o, u in product((0, 1), repeat=3):
        weight = _bernoulli(GOAL_SIDE_PROBABILITY, z) * _bernoulli(ORIENTATION_PROBABILITY, o) * _bernoulli(wind, u)
        p_one = _as_fraction(policy(z, o, o ^ u))
        if not 0 <= p_one <= 1:
            raise InvalidValueError(f"policy(z={z}, o={o}, w={o ^ u}) must be a probability, got {p_one}")
        value += weight * (p_one * _success_probability(1 ^ z, u) + (1 - p_one) * _success_probability(z, u))
    return value


class RouteChoiceEnv(ConfoundedEnv):
    """Confounded Route Choice as a batched, single-step TorchRL env.

    Keys: observed ``"Z"`` and ``"W"``, ``("latent", "O")`` (the expert's orientation),
    ``("scm", "U")`` (the wind), the action ``"action"`` (= X), ``"reward"`` (= Y), all
    float32 in {0, 1} with shape ``batch + (1,)``. Every episode ends after one step
    (``terminated``); ``"success"`` is ``Y = 1``.

    Args:
        batch_size: batch shape.
        regime: ``"train"`` (wind 1/4) or ``"deploy"`` (wind ``1/4 + strength / 2``).
        confounding_strength: in [0, 1]; 0 makes deployment identical to training.
        horizon: must be 1 (the example is single-stage).
        device, seed: see :class:`~torchrl_causal.envs.ConfoundedEnv`.

    Examples:
        >>> env = RouteChoiceEnv(batch_size=(4,), regime="deploy", seed=0)
        >>> env.wind_probability
        Fraction(3, 4)
        >>> td = env.reset()
        >>> td["action"] = (td["Z"].long() ^ td["latent", "O"].long()).float()  # the expert
        >>> env.step(td)["next", "terminated"].all().item()
        True
    """

    runtime_attributes = (*ConfoundedEnv.runtime_attributes, "_state")

    def __init__(self, *, horizon: int = 1, **kwargs) -> None:
        if horizon != 1:
            raise InvalidValueError(f"RouteChoiceEnv is single-stage: horizon must be 1, got {horizon!r}")
        super().__init__(horizon=horizon, **kwargs)

    @property
    def wind_probability(self) -> Fraction:
        """P(U = 1) in this env's regime."""
        if self.regime == "train":
            return TRAIN_WIND
        return TRAIN_WIND + (DEPLOY_WIND - TRAIN_WIND) * _as_fraction(self.confounding_strength)

    @classmethod
    @cache
    def slice_template(cls) -> TimeSliceTemplate:
        """Z → X ← O → W; Y has parents Z, X and shares the wind with W (W ↔ Y)."""
        from torchrl_causal.graphs import TimeSliceTemplate

        return TimeSliceTemplate(
            variables=("Z", "O", "W", "X"),
            action="X",
            observed=("Z", "W", "X"),
            directed=(("Z", "X", 0), ("O", "X", 0), ("O", "W", 0)),
            reward_parents=("Z", "X"),
            reward_bidirected=("W",),
        )

    def _binary_spec(self) -> Binary:
        return Binary(n=1, shape=(*self.batch_size, 1), device=self.device, dtype=torch.float32)

    def _make_variable_specs(self):
        variables = {key: self._binary_spec() for key in ("Z", "W", ("latent", "O"), ("scm", "U"))}
        return self._binary_spec(), variables

    def _draw(self, probability: Fraction) -> torch.Tensor:
        uniform = torch.rand((*self.batch_size, 1), generator=self.rng, device=self.device)
        return (uniform < float(probability)).to(torch.float32)

    def _reset_state(self, mask: torch.Tensor) -> None:
        fresh = {
            "Z": self._draw(GOAL_SIDE_PROBABILITY),
            "O": self._draw(ORIENTATION_PROBABILITY),
            "U": self._draw(self.wind_probability),
        }
        state = getattr(self, "_state", fresh)
        self._state = {name: torch.where(mask, fresh[name], state[name]) for name in fresh}

    def _transition(self, action: torch.Tensor, live: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        # Every row is computed, a partial step's skipped ones too: all the state lives in
        # runtime_attributes, which the base puts back in the rows ``live`` does not set.
        z, wind = self._state["Z"], self._state["U"]
        route = (action.round() != z).to(torch.float32)  # A = X xor Z
        # Y's parents are {X, Z, U}: the route (X, Z) and the wind U.
        success_probability = route * float(SHELTERED_SUCCESS) + (1 - route) * (1 - wind)
        outcome = torch.rand(z.shape, generator=self.rng, device=self.device) < success_probability
        return outcome.to(torch.float32), outcome

    def _terminated(self, success: torch.Tensor) -> torch.Tensor:
        return torch.ones_like(success)  # single stage: Y is decided after the one action

    def _observation(self) -> dict[str, object]:
        orientation, wind = self._state["O"], self._state["U"]
        compass = (orientation != wind).to(torch.float32)  # W = O xor U: a collider of O and U
        return {
            "Z": self._state["Z"].clone(),
            "W": compass,
            "latent": {"O": orientation.clone()},
            "scm": {"U": wind.clone()},
        }

    #: reported by :meth:`config`, set by the regime and the strength
    derived_config_keys = ("wind_probability",)

    def config(self) -> dict[str, object]:
        """:meth:`ConfoundedEnv.config`, plus ``"wind_probability"``."""
        return {**super().config(), "wind_probability": str(self.wind_probability)}
