"""Causal BC's checkpoint selection and recipes, without an env: the trainers' own selection code
driven by scripted scores and a synthetic regression set, checked against brute force."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from omegaconf import OmegaConf
from tensordict import TensorDict
from torch import nn
from torchrl.data import Bounded

from torchrl_causal.experiment import RunDirectory, compose_config, load_checkpoint
from torchrl_causal.graphs.window import AdjustmentWindow
from torchrl_causal.modules import make_deterministic_actor
from torchrl_causal.modules.networks import ResidualBlock, ResidualMLP
from torchrl_causal.objectives import HuberBCLoss
from torchrl_causal.trainers import BCTrainer

SPEC = Bounded(-1.0, 1.0, shape=(2,))
OBS_DIM = 3


def _cfg(*, by_success: bool = False, by_val_loss: bool = False, epochs: int = 40, patience: int = 3):
    return OmegaConf.create(
        {
            "device": "cpu",
            "checkpoint_every_s": 3600,
            "eval": {"select_by_success": by_success},
            "algo": {"epochs": epochs, "patience": patience, "batch_size": 16, "select_by_val_loss": by_val_loss, "precision": None},
        }
    )


def _trainer(tmp_path: Path, cfg, scores=()) -> BCTrainer:
    """A BC trainer whose periodic evaluation returns ``scores`` in turn, set up by hand on a
    synthetic regression set (train and validation rows drawn independently, noisy actions:
    a 64-wide actor overfits it within a few epochs, so the validation loss turns up)."""
    scripted = iter(scores)

    def evaluate(policy):
        success_rate, return_mean = next(scripted)
        return SimpleNamespace(success_rate=success_rate, return_mean=return_mean)

    window = AdjustmentWindow(k=0, action="X", lags={"P": (0,)}, excluded=frozenset(), exact=False, observed=("P", "X"))
    trainer = BCTrainer(cfg, RunDirectory(tmp_path / "run"), window, evaluate)
    torch.manual_seed(0)
    actor = make_deterministic_actor(OBS_DIM, SPEC, hidden=64, num_blocks=1)
    trainer.loss = HuberBCLoss(actor)
    trainer.optimizer = torch.optim.Adam(trainer.loss.parameters(), lr=1e-3)
    trainer.generator = torch.Generator().manual_seed(0)

    def rows(n: int) -> TensorDict:
        observation = torch.randn(n, OBS_DIM)
        action = (0.5 * torch.tanh(observation[:, :2]) + 0.4 * torch.randn(n, 2)).clamp(-1, 1)
        return TensorDict({"observation": observation, "action": action}, [n])

    trainer.train_data, trainer.val_data = rows(96), rows(96)
    trainer.best_val_loss, trainer.epochs_without_improvement = math.inf, 0
    trainer.logger = SimpleNamespace(log_scalar=lambda *args, **kwargs: None)
    return trainer


def _brute_force_selection(scores: list[tuple[float, float]], by_success: bool) -> int:
    """The 1-based index of the best score: the highest success, then the highest return, then
    the earliest (by return alone when not ``by_success``)."""
    keys = [(success, return_mean) if by_success else (return_mean,) for success, return_mean in scores]
    return keys.index(max(keys)) + 1


@settings(max_examples=12, deadline=None)
@given(
    by_success=st.booleans(),
    # few distinct values so that ties in success, in return and in both occur
    scores=st.lists(st.tuples(st.sampled_from([0.0, 0.25, 0.5, 1.0]), st.sampled_from([-30.0, -20.0, -10.0])), min_size=1, max_size=8),
)
def test_periodic_evaluation_keeps_the_argmax_of_a_scripted_sequence(tmp_path_factory, by_success: bool, scores) -> None:
    """Through :meth:`Trainer.periodic_evaluation` itself: the kept checkpoint is the scripted
    sequence's argmax (by success with the return breaking ties, or by return), the earliest of
    equal ones, and ``best.pt`` holds its scores and the weights the policy had then."""
    tmp_path = tmp_path_factory.mktemp("select")
    trainer = _trainer(tmp_path, _cfg(by_success=by_success), scores)
    weights = {}
    for step in range(1, len(scores) + 1):
        trainer.progress = step
        with torch.no_grad():
            for p in trainer.policy.parameters():
                p.add_(0.01)  # a policy that differs at every evaluation
        weights[step] = {k: v.clone() for k, v in trainer.policy.state_dict().items()}
        trainer.periodic_evaluation()
    expected = _brute_force_selection(list(scores), by_success)
    assert trainer.best_progress == expected
    best = load_checkpoint(trainer.run.best_checkpoint)
    assert best["progress"] == expected and (best["train_success"], best["train_return"]) == scores[expected - 1]
    for name, value in weights[expected].items():
        torch.testing.assert_close(best["policy"][name], value)


def _train(trainer: BCTrainer, every: int = 0) -> list[float]:
    """Epochs until the budget or early stopping, as the base loop runs them; the validation loss
    of each epoch."""
    val = []
    while trainer.progress < trainer.total and not trainer.stopped:
        val.append(trainer.train_step()["val/loss_bc"])
        if every and trainer.progress % every == 0:
            trainer.periodic_evaluation()
    return val


def test_selection_by_validation_loss_keeps_the_first_minimum_and_its_weights(tmp_path: Path) -> None:
    """``algo.select_by_val_loss``: ``best.pt`` is the epoch of the lowest validation loss (the
    first of equal ones), its weights give that loss again, training stopped ``patience`` epochs
    later; the scripted evaluations, whose best is elsewhere, select nothing."""
    patience = 3
    scores = [(1.0, 0.0)] + [(0.0, -100.0)] * 40  # the first evaluation would win every other rule
    trainer = _trainer(tmp_path, _cfg(by_val_loss=True, patience=patience), scores)
    val = _train(trainer, every=1)
    argmin = min(range(len(val)), key=lambda i: (val[i], i)) + 1
    assert trainer.stopped and len(val) == argmin + patience < trainer.total  # the set overfits: a real minimum
    assert argmin > 1  # the minimum is not the first evaluation, which selection by score would keep
    best = load_checkpoint(trainer.run.best_checkpoint)
    assert trainer.best_progress == best["progress"] == argmin and best["val_loss"] == val[argmin - 1]
    assert math.isnan(best["train_return"]) and math.isnan(best["train_success"])  # not evaluated by the rule
    trainer.policy.load_state_dict(best["policy"])
    assert trainer.validation_loss() == pytest.approx(val[argmin - 1], rel=1e-6)
    assert trainer.best_return == -math.inf  # the evaluations kept no score


def test_early_stopping_reads_the_validation_loss_whatever_the_selection(tmp_path: Path) -> None:
    """Selection by success leaves early stopping as it was: the same epochs, the same stop, and
    the kept policy is the best evaluation among those epochs only."""
    runs = {}
    for by_success in (False, True):
        scores = [(0.1 * (i % 5), -float(i)) for i in range(40)]
        trainer = _trainer(tmp_path / str(by_success), _cfg(by_success=by_success, patience=3), scores)
        runs[by_success] = (_train(trainer, every=1), trainer.best_progress)
    (val_return, best_return), (val_success, best_success) = runs[False], runs[True]
    assert val_return == val_success and 5 <= len(val_return) < 40  # stopped early, identically
    evaluated = scores[: len(val_return)]
    assert best_return == _brute_force_selection(evaluated, False) == 1  # by return: -0 is the highest
    assert best_success == _brute_force_selection(evaluated, True) == 5  # by success: 0.4 first reached at epoch 5


def test_the_paper_recipe_builds_appendix_e_s_bc_over_the_cpu_scale() -> None:
    """``+recipe=bc_paper`` on ``scale=cpu_ant`` (whose BC actor is 128 x 2): 4 residual blocks
    of width 256 without dropout, Huber, Adam 3e-4, batch 2048, 100 epochs, patience 15, a 20%
    validation split, selection by validation loss; the default keeps the scale's actor."""
    base = ["env=antmaze_medium", "+row=c_bc", "scale=cpu_ant"]
    default, paper = compose_config(base), compose_config([*base, "+recipe=bc_paper"])
    assert (default.algo.actor.hidden, default.algo.actor.num_blocks, default.algo.select_by_val_loss) == (128, 2, False)
    algo = paper.algo
    assert (algo.batch_size, algo.epochs, algo.patience, algo.val_fraction, algo.optimizer.lr) == (2048, 100, 15, 0.2, 3e-4)
    assert algo.select_by_val_loss and algo.loss._target_.endswith("HuberBCLoss") and not paper.eval.select_by_success
    from hydra.utils import instantiate

    actor = instantiate(algo.actor)(OBS_DIM, SPEC)
    (body,) = [m for m in actor.modules() if isinstance(m, ResidualMLP)]
    blocks = [m for m in body.modules() if isinstance(m, ResidualBlock)]
    assert len(blocks) == 4 and body.projection.out_features == 256 and body.head.in_features == 256
    assert all(isinstance(m, nn.Dropout) and m.p == 0.0 for b in blocks for m in b.body if isinstance(m, nn.Dropout))
    assert sum(p.numel() for p in body.parameters()) == (OBS_DIM + 1) * 256 + 4 * (2 * 2 * 256 + 2 * (256 + 1) * 256) + 257 * 2


def test_the_long_recipe_turns_early_stopping_off_and_selects_by_success() -> None:
    cfg = compose_config(["env=antmaze_large", "+row=c_bc", "scale=cpu_ant", "+recipe=[bc_paper,bc_long_by_success]", "algo.epochs=500"])
    assert (cfg.algo.epochs, cfg.algo.patience, cfg.algo.actor.num_blocks) == (500, 500, 4)
    assert cfg.eval.select_by_success and not cfg.algo.select_by_val_loss
