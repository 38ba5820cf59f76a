"""torchrl-causal: TorchRL components for causal imitation learning under unobserved confounding.

Layout (each imports only what stands before it): ``graphs`` (pure Python causal machinery) →
``envs`` (the confounded envs) → ``transforms``, ``modules``, ``objectives``, ``data`` →
``experiment`` (configs and run directories) → ``experts`` (the planner, the experts, the
walking skills and their trainers) → ``trainers``, ``evaluation`` → ``lifecycle`` → ``cli``
(``tests/test_structure.py`` holds the package to it). Causal knowledge enters training through
one door: the :class:`~torchrl_causal.graphs.AdjustmentWindow` that ``graphs`` computes and
:class:`~torchrl_causal.transforms.CausalWindowTransform` applies.
"""

import logging
import os

__version__ = "0.1.0"


def _quiet_third_party_notices() -> None:
    """Silences two notices every import would print, leaving real warnings alone.

    * gymnasium-robotics prints a note about the Adroit hand envs' rewards to stderr on
      import (through ``farama_notifications``); this library uses no Adroit env, so only
      that note is dropped, before gymnasium-robotics is imported.
    * TorchRL logs routine INFO lines (e.g. "Initialized LazyTensorStorage") in ANSI
      colour on stdout. Its logger keeps WARNING and above; a user who sets
      ``RL_LOGGING_LEVEL`` chooses the level themselves.
    """
    try:
        from farama_notifications import notifications
    except ImportError:
        pass
    else:
        robotics = notifications.get("gymnasium_robotics", {})
        for version in [v for v, note in robotics.items() if "AdroitHand" in note]:
            del robotics[version]
    if "RL_LOGGING_LEVEL" not in os.environ:
        logging.getLogger("torchrl").addFilter(_warnings_and_above)


def _warnings_and_above(record: logging.LogRecord) -> bool:
    return record.levelno >= logging.WARNING


_quiet_third_party_notices()
