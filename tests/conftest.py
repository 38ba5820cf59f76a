"""Fixtures shared by the test modules."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import torch


@pytest.fixture
def torch_threads() -> Iterator[None]:
    """Gives the test back torch's thread count as it found it (CLIs set it process-wide)."""
    threads = torch.get_num_threads()
    yield
    torch.set_num_threads(threads)
