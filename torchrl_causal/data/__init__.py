"""Expert demonstrations: collection, atomic memory-mapped storage and verified loading."""

from torchrl_causal.data.demonstrations import (
    FORMAT_VERSION,
    DatasetError,
    collect_demonstrations,
    load_demonstrations,
    read_metadata,
    successful_episodes,
)

__all__ = ["FORMAT_VERSION", "DatasetError", "collect_demonstrations", "load_demonstrations", "read_metadata",
           "successful_episodes"]
