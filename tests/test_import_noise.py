"""Importing the package prints nothing of its own dependencies' routine notices."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

SCRIPT = """
import logging, warnings
import torch
from tensordict import TensorDict
import torchrl_causal.envs  # gymnasium-robotics and torchrl underneath
from torchrl.data import LazyTensorStorage

LazyTensorStorage(4).set(range(4), TensorDict({"x": torch.zeros(4)}, [4]))  # torchrl logs this at INFO
logging.getLogger("torchrl").warning("a real torchrl warning")
warnings.warn("a real python warning")
"""


def test_imports_are_quiet_and_real_warnings_still_show():
    result = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, cwd=Path(__file__).parents[1], timeout=240)
    assert result.returncode == 0, result.stderr
    output = result.stdout + result.stderr
    assert "Adroit" not in output and "Initialized LazyTensorStorage" not in output
    assert "a real torchrl warning" in output and "a real python warning" in output
