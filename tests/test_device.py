"""Device plumbing: ``device=`` resolution and its refusal before anything is written,
placement of every parameter, optimiser state and sampled batch, on-device loss averaging
with a log every N updates, the compiled update, and multi-process collection.

The placement tests run on every device this machine has: the CPU always (the CI
machine has no GPU), CUDA when present.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from functools import partial
from pathlib import Path

import pytest
import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModule
from test_trainers import build_trainer, tiny_config
from torchrl.data import Bounded
from torchrl.objectives import SoftUpdate

from torchrl_causal.evaluation.evaluator import Evaluator
from torchrl_causal.evaluation.runs import read_scalar_csv
from torchrl_causal.experiment import RunDirectory, compose_config
from torchrl_causal.experiment.device import PolicyOnDevice, bf16_unavailable, compile_unavailable, for_cpu_env, resolve_device
from torchrl_causal.experiment.schema import ConfigValueError, validate_config
from torchrl_causal.experiment.timing import PartTimer
from torchrl_causal.lifecycle import run
from torchrl_causal.modules import make_qvalue_network, make_tanh_gaussian_actor
from torchrl_causal.objectives import IQLearnLoss, SQILLoss
from torchrl_causal.trainers import Trainer
from torchrl_causal.trainers.update import ActorCriticUpdate

DEVICES = ["cpu", *(["cuda"] if torch.cuda.is_available() else [])]
REPO = Path(__file__).resolve().parents[1]


def set_up(cfg) -> Trainer:
    """The trainer of ``cfg`` as :meth:`Trainer.fit` has it before its loop."""
    trainer = build_trainer(cfg)
    trainer.setup()
    return trainer


def assert_on(device: torch.device, tensors: dict[str, torch.Tensor]) -> None:
    misplaced = {name: str(t.device) for name, t in tensors.items() if t.device != device}
    assert not misplaced, f"not on {device}: {misplaced}"


def module_tensors(module: torch.nn.Module) -> dict[str, torch.Tensor]:
    return {**dict(module.named_parameters()), **dict(module.named_buffers())}


def optimizer_tensors(optimizer: torch.optim.Optimizer) -> dict[str, torch.Tensor]:
    # Adam's "step" counter lives on the CPU unless the step is fused or capturable.
    return {
        f"{i}.{key}": value
        for i, state in enumerate(optimizer.state.values())
        for key, value in state.items()
        if key != "step" and isinstance(value, torch.Tensor)
    }


def batch_tensors(batch: TensorDictBase) -> dict[str, torch.Tensor]:
    return {str(key): value for key, value in batch.items(True, True)}


# ---------------------------------------------------------------------------- resolution


def test_resolve_device_names_and_auto() -> None:
    assert resolve_device("cpu") == torch.device("cpu")
    assert resolve_device(torch.device("cpu")) == torch.device("cpu")
    expected = torch.device("cuda", 0) if torch.cuda.is_available() else torch.device("cpu")
    assert resolve_device("auto") == resolve_device(" Auto ") == expected
    if torch.cuda.is_available():
        assert resolve_device("cuda") == torch.device("cuda", torch.cuda.current_device())


@pytest.mark.parametrize("name", ["gpu", "cuda:x", "", "cpu:0:1"])
def test_resolve_device_refuses_what_is_not_a_device(name: str) -> None:
    with pytest.raises(ValueError, match=f"device={name!r} is not a device name"):
        resolve_device(name)


def test_resolve_device_refuses_devices_this_machine_lacks() -> None:
    with pytest.raises(ValueError, match=r"device='cuda:999' cannot be used here"):
        resolve_device("cuda:999")
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match=r"device='cuda' cannot be used here: torch.cuda.is_available\(\) is False"):
            resolve_device("cuda")
    if not torch.backends.mps.is_available():
        with pytest.raises(ValueError, match=r"device='mps' cannot be used here"):
            resolve_device("mps")
    with pytest.raises(ValueError, match="only cpu, cuda, cuda:N, mps and auto"):
        resolve_device("meta")


def test_trainer_refuses_a_missing_device_before_writing(tmp_path: Path) -> None:
    cfg = tiny_config(tmp_path, "route_choice", "bc", True, "device=cuda:999")
    with pytest.raises(ValueError, match="device='cuda:999'"):
        run(cfg)
    assert list(tmp_path.iterdir()) == []


def test_cli_refuses_a_missing_device_before_hydra_makes_the_run_directory(tmp_path: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    root = tmp_path / "runs"
    for mode in ([], ["-m", "seed=0,1"]):
        done = subprocess.run(
            [sys.executable, "-m", "torchrl_causal.train", *mode, "env=route_choice", "algo=bc", "device=cuda:999", f"run_root={root}"],
            capture_output=True,
            text=True,
            env=env,
            cwd=tmp_path,
            timeout=240,
        )
        assert done.returncode != 0
        assert "device='cuda:999' cannot be used here" in done.stderr, done.stderr[-2000:]
        assert not root.exists(), sorted(str(p) for p in root.rglob("*"))


# ---------------------------------------------------------------------------- placement


@pytest.mark.parametrize("device", DEVICES)
def test_off_policy_placement_of_every_parameter_and_sampled_batch(tmp_path: Path, device: str) -> None:
    cfg = tiny_config(tmp_path, "rovermaze_u", "iq_learn", True, f"device={device}")
    trainer = set_up(cfg)
    target = resolve_device(device)
    assert trainer.device == target
    while trainer.update.updates == 0:  # through the random phase into the first updates
        trainer.train_step()
    assert_on(target, module_tensors(trainer.loss))  # actor, twin critics, targets, alpha
    assert_on(target, module_tensors(trainer.policy))
    for optimizer in trainer.update.optimizers:
        assert optimizer.state, "no optimiser state after an update"
        assert_on(target, optimizer_tensors(optimizer))
    assert_on(target, batch_tensors(trainer.expert_buffer.sample()))
    assert_on(target, batch_tensors(trainer.policy_buffer.sample()))
    assert_on(target, batch_tensors(next(trainer.batches)))  # the collector stores on the device
    # The evaluation env steps on the CPU.
    assert Evaluator(cfg, trainer.window).evaluate(trainer.policy, "train", 2, 0).n_episodes == 2

    # A checkpoint loads onto the device, the replay buffer's storage included.
    state = trainer.state_dict()
    trainer.close()
    resumed = set_up(cfg)
    resumed.load_state_dict(state)
    assert resumed.update.updates == trainer.update.updates
    assert_on(target, module_tensors(resumed.loss))
    for optimizer in resumed.update.optimizers:
        assert_on(target, optimizer_tensors(optimizer))
    assert_on(target, batch_tensors(resumed.policy_buffer.sample()))
    resumed.close()


@pytest.mark.parametrize("device", DEVICES)
def test_bc_and_gail_placement(tmp_path: Path, device: str) -> None:
    target = resolve_device(device)
    bc = set_up(tiny_config(tmp_path, "rovermaze_u", "bc", True, f"device={device}"))
    bc.train_step()
    assert_on(target, module_tensors(bc.loss))
    assert_on(target, optimizer_tensors(bc.optimizer))
    assert_on(target, {**batch_tensors(bc.train_data), **batch_tensors(bc.val_data)})
    gail = set_up(tiny_config(tmp_path, "rovermaze_u", "gail", True, f"device={device}"))
    gail.train_step()
    assert_on(target, {**module_tensors(gail.losses.policy), **module_tensors(gail.losses.discriminator)})
    assert_on(
        target,
        {
            **optimizer_tensors(gail.actor_optimizer),
            **optimizer_tensors(gail.critic_optimizer),
            **optimizer_tensors(gail.discriminator_optimizer),
        },
    )
    assert_on(target, batch_tensors(gail.expert))
    gail.close()


def test_evaluation_moves_only_policies_that_live_off_the_cpu() -> None:
    on_cpu = TensorDictModule(torch.nn.Linear(3, 2), in_keys=["observation"], out_keys=["action"])
    assert for_cpu_env(on_cpu) is on_cpu
    scripted = TensorDictModule(torch.nn.Identity(), in_keys=["observation"], out_keys=["action"])  # no parameters
    assert for_cpu_env(scripted) is scripted
    off_cpu = TensorDictModule(torch.nn.Linear(3, 2, device="meta"), in_keys=["observation"], out_keys=["action"])
    wrapped = for_cpu_env(off_cpu)
    assert isinstance(wrapped, PolicyOnDevice) and wrapped.device == torch.device("meta")
    td = TensorDict({"observation": torch.ones(4, 3), "other": torch.zeros(4)}, [4])
    out = PolicyOnDevice(on_cpu, "cpu")(td.clone())
    torch.testing.assert_close(out["action"], on_cpu(td.clone())["action"])
    assert "other" in out.keys()


# ---------------------------------------------------------------------------- no syncs, logging


_READS = ("item", "tolist", "__bool__", "__float__", "__int__", "__index__")


def test_update_loop_reads_nothing_back_from_tensors(tmp_path: Path, monkeypatch) -> None:
    """Between logs, the trainer's own code converts no tensor to a Python value (on a
    GPU each such read would wait for the device)."""
    trainer = set_up(tiny_config(tmp_path, "rovermaze_u", "sqil", True, "log_every=1000"))
    while trainer.progress < int(trainer.cfg.algo.random_steps):
        trainer.train_step()
    trainers_dir = str(REPO / "torchrl_causal" / "trainers")
    reads: list[str] = []
    for name in _READS:
        original = getattr(torch.Tensor, name)

        def counting(self, *args, _name=name, _original=original, **kwargs):
            caller = sys._getframe(1).f_code
            if caller.co_filename.startswith(trainers_dir):
                reads.append(f"{_name} in {caller.co_name} ({Path(caller.co_filename).name})")
            return _original(self, *args, **kwargs)

        monkeypatch.setattr(torch.Tensor, name, counting)
    before = trainer.update.updates
    scalars = trainer.train_step()
    monkeypatch.undo()
    assert trainer.update.updates - before == 10 and scalars == {}
    assert reads == []
    trainer.close()


def test_losses_are_averaged_on_device_and_logged_every_n_updates(tmp_path: Path, monkeypatch) -> None:
    recorded: list[torch.Tensor] = []
    step = ActorCriticUpdate.__call__

    def recording(self, batch):
        scalars = step(self, batch)
        recorded.append(scalars.clone())
        return scalars

    monkeypatch.setattr(ActorCriticUpdate, "__call__", recording)
    # 80 random steps, then 10 updates per 40-step collector batch up to 240 steps.
    cfg = tiny_config(tmp_path, "rovermaze_u", "sqil", True, "log_every=15")
    run(cfg)
    scalars = Path(cfg.run_dir) / "logs" / "scalars" / "train"
    assert len(recorded) == 40
    # 20 updates by step 160 (>= 15: logged), 10 more by 200 (not), 20 by 240 (logged, the end).
    windows = {160: torch.stack(recorded[:20]).mean(0), 240: torch.stack(recorded[20:]).mean(0)}
    for index, name in enumerate(ActorCriticUpdate.SCALARS):
        logged = read_scalar_csv(scalars / f"{name}.csv")
        assert [s for s, _ in logged] == [160, 240], name
        for s, value in logged:
            assert value == pytest.approx(windows[s][index].item(), rel=1e-5, abs=1e-6), (name, s)
    # The collection scalar is logged through the random phase too.
    assert [s for s, _ in read_scalar_csv(scalars / "reward_per_step.csv")] == [40, 80, 160, 240]


# ---------------------------------------------------------------------------- torch.compile


COMPILE_UNAVAILABLE = compile_unavailable(torch.device("cpu"))


def test_compile_without_a_cxx_compiler_is_refused_before_a_run_directory_exists(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.delenv("CXX", raising=False)
    monkeypatch.setattr(shutil, "which", lambda name: None)
    assert "needs a C++ compiler" in compile_unavailable(torch.device("cpu"))
    cfg = compose_config([f"run_root={tmp_path}", "env=route_choice", "algo=sqil", "compile=true"])
    with pytest.raises(ConfigValueError, match="compile=true cannot run on cpu here: .*C\\+\\+ compiler"):
        run(cfg)
    assert not any(tmp_path.iterdir())
    validate_config(compose_config([f"run_root={tmp_path}", "env=route_choice", "algo=sqil", "compile=false"]))


def _recipe_update(compile: bool, loss_class: type = IQLearnLoss, precision: str = "fp32") -> ActorCriticUpdate:
    torch.manual_seed(0)
    spec = Bounded(-1.0, 1.0, shape=(2,))
    loss = loss_class(
        make_tanh_gaussian_actor(3, spec, hidden=16, num_blocks=1, dropout=0.05),
        make_qvalue_network(3, spec, hidden=16, num_blocks=1),
        goal_value="expert",
        bc_weight=0.4,
        **({"num_value_samples": 2} if loss_class is IQLearnLoss else {}),
    )  # the recipe's options: they once split the graph
    loss.make_value_estimator(gamma=0.99)
    adam = partial(torch.optim.Adam, lr=1e-2)
    return ActorCriticUpdate(
        loss,
        actor_optimizer=adam,
        critic_optimizer=adam,
        alpha_optimizer=adam,
        target_update=partial(SoftUpdate, tau=0.1),
        max_grad_norm=1.0,
        critic_scheduler=torch.optim.lr_scheduler.CosineAnnealingLR,
        cosine_updates=5,
        compile=compile,
        precision=precision,
    )


def _batches(count: int) -> list[TensorDict]:
    generator = torch.Generator().manual_seed(1)
    return [
        TensorDict(
            {
                "observation": torch.randn(8, 3, generator=generator),
                "action": torch.rand(8, 2, generator=generator) * 2 - 1,
                "expert": (torch.arange(8) < 4).unsqueeze(-1),
                "next": {
                    "observation": torch.randn(8, 3, generator=generator),
                    "done": (torch.arange(8) % 4 == 3).unsqueeze(-1),
                    "terminated": (torch.arange(8) % 4 == 3).unsqueeze(-1),
                },
            },
            [8],
        )
        for _ in range(count)
    ]


@pytest.mark.skipif(COMPILE_UNAVAILABLE is not None, reason=str(COMPILE_UNAVAILABLE))
def test_compiled_update_matches_eager() -> None:
    """Same seed, same batches: compiled and eager updates give the same losses and weights.

    IQ-Learn is the loss compiled here: its graph holds SAC's actor and temperature
    losses and the K-sample soft value (one compilation costs ~30 s of CPU, so one loss),
    with the recipe's goal value (a goal-terminated row in each half) and anchor: reading
    the discount as a tensor once split that graph, and the backward then failed.
    Dropout (0.05) and the action samples draw from the RNG, so this also checks that
    the compiled step keeps eager's random stream.
    """
    results = {}
    for compile in (False, True):
        update = _recipe_update(compile)
        torch.manual_seed(2)
        scalars = torch.stack([update(batch) for batch in _batches(3)])
        results[compile] = scalars, {k: v.detach().clone() for k, v in update.loss.state_dict().items()}
    torch.testing.assert_close(results[True][0], results[False][0], rtol=1e-5, atol=1e-5)
    for key, value in results[False][1].items():
        torch.testing.assert_close(results[True][1][key], value, rtol=1e-5, atol=1e-5, msg=key)
    assert not torch.equal(results[False][1]["log_alpha"], torch.zeros(()))  # the updates did move things


# Two graphs: ~40 s of CPU, and inductor's C++ compiler besides. Its wall time is whatever CPU
# the machine spares (48 min at a niced sliver of two busy cores), so no wall-clock limit.
@pytest.mark.slow
@pytest.mark.timeout(0)
@pytest.mark.skipif(COMPILE_UNAVAILABLE is not None, reason=str(COMPILE_UNAVAILABLE))
def test_the_compiled_warm_start_critic_phase_matches_eager() -> None:
    """The warm start's critic-only steps compiled (a graph of their own) give eager's
    critic losses, and the joint update compiled after them in the same process (the
    trainer's order) gives eager's scalars and weights: the recipe's IQ-Learn loss, dropout on."""
    results = {}
    for compile in (False, True):
        update = _recipe_update(compile)
        torch.manual_seed(2)
        critic = torch.stack([update.critic_step(batch) for batch in _batches(3)])
        joint = torch.stack([update(batch) for batch in _batches(2)])
        results[compile] = critic, joint, {k: v.detach().clone() for k, v in update.loss.state_dict().items()}
    assert update.updates == 2 and not torch.equal(results[True][0][0], results[True][0][-1])
    torch.testing.assert_close(results[True][0], results[False][0], rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(results[True][1], results[False][1], rtol=1e-5, atol=1e-5)
    for key, value in results[False][2].items():
        torch.testing.assert_close(results[True][2][key], value, rtol=1e-5, atol=1e-5, msg=key)


# ---------------------------------------------------------------------------- bf16


BF16_UNAVAILABLE = bf16_unavailable(torch.device("cpu"))


def test_a_bf16_update_runs_its_matmuls_in_bf16_and_keeps_its_state_in_fp32() -> None:
    """``precision="bf16"``: every linear layer of the loss computes in bf16, while the
    losses, the parameters, their gradients and Adam's moments stay fp32; from the same
    state and draws, its losses are the fp32 update's to bf16's ~3 significant digits."""
    scalars, states = {}, {}
    for precision in ("fp32", "bf16"):
        update = _recipe_update(False, loss_class=SQILLoss, precision=precision)
        seen: set[torch.dtype] = set()
        networks = (update.loss.actor_network, update.loss.qvalue_network)
        linears = [m for network in networks for m in network.modules() if isinstance(m, torch.nn.Linear)]
        hooks = [m.register_forward_hook(lambda m, i, o: seen.add(o.dtype)) for m in linears]
        torch.manual_seed(2)
        batch = _batches(1)[0]
        with torch.no_grad():
            total, _ = update.losses(batch.clone())
        assert total.dtype == torch.float32
        torch.manual_seed(2)
        scalars[precision] = update(batch)
        for hook in hooks:
            hook.remove()
        assert seen == {torch.bfloat16 if precision == "bf16" else torch.float32}, precision
        params = [*update.critic_params, *update.actor_params, update.loss.log_alpha]
        assert all(p.dtype == torch.float32 and (p.grad is None or p.grad.dtype == torch.float32) for p in params)
        moments = [t for o in update.optimizers for s in o.state.values() for t in s.values() if t.ndim]
        assert moments and all(t.dtype == torch.float32 for t in moments)
        states[precision] = {k: v.detach().clone() for k, v in update.loss.state_dict().items()}
    assert scalars["bf16"].dtype == torch.float32
    torch.testing.assert_close(scalars["bf16"], scalars["fp32"], rtol=2e-2, atol=1e-3)
    assert not torch.equal(scalars["bf16"], scalars["fp32"])  # bf16 did run: the numbers differ


def test_bf16_is_refused_in_one_line_where_the_cpu_lacks_native_bf16(tmp_path: Path, monkeypatch) -> None:
    from torchrl_causal.experiment import schema

    monkeypatch.setattr(schema, "bf16_unavailable", lambda device: bf16_unavailable(device, cpu_flags=frozenset({"avx2", "fma"})))
    cfg = compose_config([f"run_root={tmp_path}", "env=route_choice", "algo=sqil", "algo.precision=bf16"])
    with pytest.raises(ConfigValueError, match=r"^algo.precision=bf16 cannot run natively on cpu here: .*avx512_bf16 nor amx_bf16[^\n]*$"):
        run(cfg)
    assert not any(tmp_path.iterdir())
    validate_config(compose_config([f"run_root={tmp_path}", "env=route_choice", "algo=sqil", "algo.precision=fp32"]))


@pytest.mark.skipif(BF16_UNAVAILABLE is not None, reason=str(BF16_UNAVAILABLE))
def test_a_run_records_its_precision_and_the_cost_of_its_parts(tmp_path: Path) -> None:
    """A tiny BC run with ``algo.precision=bf16`` records it beside ``compile`` and
    ``device``; a :class:`PartTimer` recording the run splits its whole time into parts."""
    cfg = tiny_config(tmp_path, "rovermaze_u", "bc", True, "algo.epochs=2", "algo.precision=bf16")
    timer = PartTimer()
    with timer.recording():
        run(cfg)
    attempt = RunDirectory(cfg.run_dir).read_attempts()[-1]
    assert (attempt["precision"], attempt["compile"], attempt["device"]) == ("bf16", False, "cpu")
    assert {"setup", "updates", "evaluation", "checkpoints"} <= set(timer.cpu)
    assert timer.calls["updates"] == 2 and min(timer.wall.values()) >= 0
    assert sum(timer.wall.values()) == pytest.approx(timer.total_wall) and timer.total_wall > 0


# ---------------------------------------------------------------------------- collection


def test_multi_process_collection_uses_the_current_policy(tmp_path: Path) -> None:
    """Two env processes (MultiSyncCollector): each batch holds both workers' envs, the
    random phase is split between them, and after the main process changes the actor the
    workers act with the new weights."""
    cfg = tiny_config(tmp_path, "rovermaze_u", "sqil", True, "collector_workers=2", "algo.random_steps=40", "algo.total_steps=120")
    trainer = set_up(cfg)
    trainer.train_step()  # the random phase: one 40-step batch, 20 steps from each worker's env
    assert trainer.progress == 40 and len(trainer.policy_buffer) == 40
    first, second = trainer.policy_buffer[:20], trainer.policy_buffer[20:40]
    assert not torch.equal(first["observation"], second["observation"])  # two differently seeded envs
    # A near-deterministic actor: zero weights, pre-tanh mean 0.5 from the head's bias and the
    # smallest scale the actor allows (TorchRL's lower bound 1e-4; log-std -20 is below it).
    with torch.no_grad():
        for name, param in trainer.policy.named_parameters():
            param.fill_(-20.0 if name.endswith("scale") else 0.5 if name.endswith("head.bias") else 0.0)
    trainer.train_step()
    trainer.close()
    actions = trainer.policy_buffer[40:80]["action"]
    low, high = trainer.env.action_spec.space.low, trainer.env.action_spec.space.high
    expected = (low + (high - low) * (torch.tanh(torch.tensor(0.5)) + 1) / 2).expand_as(actions)
    torch.testing.assert_close(actions, expected, atol=1e-3, rtol=0)  # > 10 standard deviations
    assert not torch.allclose(trainer.policy_buffer[:40]["action"], expected[:40], atol=1e-2)  # random phase


def test_a_run_resolves_its_device_once_for_the_trainer_and_the_evaluator(tmp_path: Path, monkeypatch) -> None:
    import torchrl_causal.evaluation.evaluator as evaluator_module
    import torchrl_causal.lifecycle as lifecycle_module
    import torchrl_causal.trainers.base as trainer_module

    calls = {module.__name__: 0 for module in (lifecycle_module, trainer_module, evaluator_module)}
    for module in (lifecycle_module, trainer_module, evaluator_module):

        def counting(spec, name=module.__name__):
            calls[name] += 1
            return resolve_device(spec)

        monkeypatch.setattr(module, "resolve_device", counting)
    run(tiny_config(tmp_path, "route_choice", "bc", True))  # trains, selects, evaluates both regimes
    assert calls == {lifecycle_module.__name__: 1, trainer_module.__name__: 0, evaluator_module.__name__: 0}


def test_a_run_from_a_missing_device_evaluates_on_the_cpu(tmp_path: Path) -> None:
    from omegaconf import OmegaConf

    from torchrl_causal.lifecycle import evaluate_run

    cfg = tiny_config(tmp_path, "route_choice", "bc", True)
    run(cfg)
    config_file = Path(cfg.run_dir) / "config.yaml"
    saved = OmegaConf.load(config_file)
    saved.device = "cuda:999"  # as if trained on a GPU this machine lacks
    config_file.write_text(OmegaConf.to_yaml(saved))
    assert evaluate_run(cfg.run_dir, "deploy", 8, num_envs=4, save=False).n_episodes == 8
    with pytest.raises(ValueError, match="device='cuda:999'"):
        evaluate_run(cfg.run_dir, "deploy", 8, num_envs=4, save=False, device="cuda:999")
