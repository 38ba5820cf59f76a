"""Causal diagrams and sequential pi-backdoor adjustment (pure Python + networkx, no torch).

The public entry points: :class:`TimeSliceTemplate` describes one step of an env,
:func:`windowed_adjustment` turns it into the :class:`AdjustmentWindow` that
:class:`~torchrl_causal.transforms.CausalWindowTransform` applies, and
:func:`observation_window` gives the non-causal baselines the same format.
"""

from .adjustment import (
    BoundedInfluence,
    check_bounded_influence,
    exact_adjustment,
    observation_window,
    verification_horizons,
    windowed_adjustment,
)
from .criteria import BackdoorReport, ExactAdjustment, find_adjustment, find_ox, sequential_pi_backdoor
from .diagram import CausalDiagram, Confounder
from .errors import BoundedInfluenceError, GraphError, NotImitableError, WindowConstructionError, WindowSizeError
from .template import REWARD, TimeSliceTemplate
from .window import AdjustmentWindow

__all__ = [
    "REWARD",
    "AdjustmentWindow",
    "BackdoorReport",
    "BoundedInfluence",
    "BoundedInfluenceError",
    "CausalDiagram",
    "Confounder",
    "ExactAdjustment",
    "GraphError",
    "NotImitableError",
    "TimeSliceTemplate",
    "WindowConstructionError",
    "WindowSizeError",
    "check_bounded_influence",
    "exact_adjustment",
    "find_adjustment",
    "find_ox",
    "observation_window",
    "sequential_pi_backdoor",
    "verification_horizons",
    "windowed_adjustment",
]
