"""The walking-skill SAC trainer: a tiny humanoid run, and its resume on a "fresh machine".

Budgets are tiny (hidden 32, a few hundred steps); the checks are counts that follow from the
config in closed form, and the contents of the resume state.
"""

from __future__ import annotations

import json

import pytest
import torch

from torchrl_causal.experts.locomotion import SKILLS, train_locomotion

FRAMES = 200  # LocomotionConfig.frames_per_batch


def _config(total_steps: int, **changes):
    return SKILLS["humanoid"].config(
        total_steps=total_steps, random_steps=400, hidden=32, buffer_size=2_000, eval_every=100_000, eval_envs=2, eval_steps=20, **changes
    )


def test_resume_from_the_small_state_refills_the_buffer_then_updates(tmp_path):
    first = train_locomotion(tmp_path / "machine_a", _config(800), skill="humanoid", output=tmp_path / "a.pt")
    # 2 random batches fill the buffer to 400 (not > 400: no update), then 2 batches of 200 steps at UTD 0.5.
    assert first["steps"] == 800 and first["updates"] == 200
    state_file = tmp_path / "machine_a" / "resume_state.pt"
    assert state_file.stat().st_size < 1_000_000  # hidden 32 here; 3.9 MB at 2 x 256
    state = torch.load(state_file, weights_only=True)
    keys = set(state["loss"])
    for part in ("actor_network_params", "qvalue_network_params", "target_qvalue_network_params", "log_alpha"):
        assert any(key.startswith(part) for key in keys), part
    assert set(state["optimizers"]) == {"actor", "critic", "alpha"} and state["skill"] == "humanoid"
    assert all(state["optimizers"][name]["state"] for name in ("actor", "critic", "alpha"))  # Adam moments kept
    best = torch.load(tmp_path / "machine_a" / "best_body.pt", weights_only=True)
    assert all(torch.equal(best[key], state["best_body"][key]) for key in best)  # the best policy travels too

    # Machine B: only the small state travels. The policy refills the buffer: 2 batches (200, 400),
    # then updates resume at the 3rd batch (600 > 400): 100 updates per batch of 200 steps.
    second = train_locomotion(tmp_path / "machine_b", _config(1400), skill="humanoid", output=tmp_path / "b.pt", resume_from=state_file)
    assert second["steps"] == 1400 and second["updates"] == 200 + 100
    resumed = torch.load(tmp_path / "machine_b" / "resume_state.pt", weights_only=True)
    assert resumed["counters"]["collect_seed"] == state["counters"]["collect_seed"] + 1  # fresh episodes
    assert not torch.equal(resumed["loss"]["log_alpha"], state["loss"]["log_alpha"])  # it kept learning
    assert (tmp_path / "b.pt").exists()  # machine B exports the best body, machine A's if none beat it
    logs = json.loads((tmp_path / "machine_b" / "locomotion_config.json").read_text())
    assert logs["updates_per_step"] == 0.5


def test_resume_refuses_another_config_or_skill(tmp_path):
    # output=None (the default, spelled out): nothing is exported
    shipped = SKILLS["humanoid"].weights.read_bytes()
    train_locomotion(tmp_path / "a", _config(FRAMES), skill="humanoid", output=None)
    state_file = tmp_path / "a" / "resume_state.pt"
    with pytest.raises(ValueError, match="updates_per_step"):
        train_locomotion(tmp_path / "b", _config(2 * FRAMES, updates_per_step=1.0), skill="humanoid", output=None, resume_from=state_file)
    with pytest.raises(ValueError, match="SAC 'humanoid' skill, not SAC's 'ant'"):
        train_locomotion(tmp_path / "c", _config(2 * FRAMES), skill="ant", output=None, resume_from=state_file)
    with pytest.raises(FileNotFoundError, match="no checkpoint at .*none.pt"):  # missing, not "corrupted"
        train_locomotion(tmp_path / "d", _config(2 * FRAMES), skill="humanoid", output=None, resume_from=tmp_path / "none.pt")
    assert not any(tmp_path.rglob("*locomotion.pt")) and SKILLS["humanoid"].weights.read_bytes() == shipped


def test_the_command_line_exports_into_its_run_directory_unless_told_otherwise(tmp_path, monkeypatch):
    from torchrl_causal.experts import locomotion

    seen = {}
    monkeypatch.setattr(locomotion, "train_locomotion", lambda run_dir, config, **kw: seen.update(run_dir=run_dir, **kw) or {})
    locomotion.main(["--skill", "ant", "--run-dir", str(tmp_path / "run"), "--steps", "400"])
    assert seen["output"] == tmp_path / "run" / "export.pt"  # a trial run never replaces the shipped weights
    locomotion.main(["--skill", "ant", "--run-dir", str(tmp_path / "run"), "--output", str(tmp_path / "ship.pt")])
    assert seen["output"] == str(tmp_path / "ship.pt")
