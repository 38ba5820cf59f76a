"""The README's pipeline example runs as written: demonstrations, their encoding, both
replay buffers, the collector and the complete SQIL loop."""

from __future__ import annotations

import re
from pathlib import Path

import torch

README = Path(__file__).resolve().parents[1] / "README.md"


def readme_example() -> str:
    """The first Python block after the README's "Composing" heading."""
    text = README.read_text()
    section = text[text.index("## Composing `CausalWindowTransform`") :]
    return re.search(r"```python\n(.*?)```", section, flags=re.S).group(1)


def test_the_readme_pipeline_and_sqil_loop_run(tmp_path: Path, capsys) -> None:
    code = readme_example().replace("/tmp/rover_demos", str(tmp_path / "rover_demos"))
    namespace: dict = {}
    torch.manual_seed(0)
    exec(compile(code, str(README), "exec"), namespace)
    keys, expert, env = namespace["keys"], namespace["expert"], namespace["env"]
    # the encoded demonstrations carry exactly the keys of the env's steps (plus the expert flag)
    assert set(expert.keys(True, True)) == set(env.rollout(2).keys(True, True)) | {"expert"}
    assert set(keys) == set(env.rollout(2).keys(True, True))
    # ... and what the README prints is what it says
    printed = capsys.readouterr().out.splitlines()
    assert printed[1] == "['L', 'P', 'observation', 'success']"
    assert "torch.Size([256, 13])" in printed[2]
    losses = namespace["losses"]
    assert all(torch.isfinite(value).all() for value in losses.values())
    assert len(namespace["policy_buffer"]) == 1024
