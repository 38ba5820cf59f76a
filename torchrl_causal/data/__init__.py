"""Expert demonstrations: collection, atomic memory-mapped storage and verified loading;
Minari datasets in and out (:mod:`torchrl_causal.data.minari_format`, the ``[minari]`` extra)."""

from torchrl_causal.data.demonstrations import (
    FORMAT_VERSION,
    DatasetError,
    collect_demonstrations,
    load_demonstrations,
    policy_record,
    read_metadata,
    successful_episodes,
)
from torchrl_causal.data.minari_format import export_minari, load_minari_demonstrations

__all__ = [
    "FORMAT_VERSION",
    "DatasetError",
    "collect_demonstrations",
    "export_minari",
    "load_demonstrations",
    "load_minari_demonstrations",
    "policy_record",
    "read_metadata",
    "successful_episodes",
]
