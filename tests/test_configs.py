"""The Hydra config tree: every combination of its groups composes and validates, every
``_target_`` resolves, bad values fail at composition, scale=paper is Appendix E
exactly, overrides reach the run, experiments sweep what the paper sweeps."""

from __future__ import annotations

import itertools
import re
import subprocess
import sys
from collections.abc import Iterator, Mapping
from typing import Any

import pytest
from hydra.errors import ConfigCompositionException, MissingConfigException
from hydra.utils import get_class, get_object, instantiate
from omegaconf import OmegaConf
from omegaconf.errors import InterpolationResolutionError

from torchrl_causal.algorithms import ALGORITHMS, Row
from torchrl_causal.algorithms import ROWS as REGISTERED_ROWS
from torchrl_causal.experiment import CONFIG_DIR, ConfigValueError, compose_config, run_label, validate_config
from torchrl_causal.experiment.schema import ALGO_SCHEMAS, AlgoConfig, algo_schema
from torchrl_causal.trainers import Trainer

ENVS = (
    "rovermaze_u",
    "rovermaze_medium",
    "rovermaze_large",
    "route_choice",
    "antmaze_medium",
    "antmaze_large",
    "humanoidmaze_medium",
    "humanoidmaze_large",
)
ALGOS = ("bc", "gail", "sqil", "iq_learn", "iq_learn_garg", "expert")

# Appendix E, tab:hparams, transcribed: (key in the algo config, value) per algorithm,
# shared by both environment families.
PAPER_SHARED = {
    "bc": {"actor.hidden": 256, "actor.num_blocks": 4, "actor.dropout": 0.0, "optimizer.lr": 3e-4, "batch_size": 2048, "val_fraction": 0.2},
    "gail": {
        "actor.hidden": 256,
        "actor.num_blocks": 3,
        "actor.dropout": 0.0,  # 0.05 in the paper: see gail.yaml
        "actor_optimizer.lr": 1e-4,
        "critic_optimizer.lr": 3e-4,
        "batch_size": 1024,
        "loss.gamma": 0.99,
        "max_grad_norm": 0.5,
        "loss.clip_epsilon": 0.2,
        "loss.gae_lambda": 0.95,
        "loss.entropy_coeff": 1e-2,
        "loss.critic_coeff": 0.5,
        "loss.normalize_advantage": True,
        "discriminator_optimizer.lr": 3e-4,
        "discriminator.dropout": 0.2,
        "discriminator_epochs": 2,  # "updated 2 times per round": see gail.yaml
        "discriminator_batch_size": 1024,
        "loss.gp_lambda": 5.0,
        "discriminator_scheduler.step_size": 100,
        "discriminator_scheduler.gamma": 0.5,
    },
    "sqil": {
        "actor.hidden": 256,
        "actor.num_blocks": 3,
        "actor.dropout": 0.05,
        "critic.hidden": 256,
        "critic.num_blocks": 3,
        "actor_optimizer.lr": 3e-4,
        "critic_optimizer.lr": 3e-4,
        "batch_size": 256,
        "value_estimator.gamma": 0.99,
        "max_grad_norm": 1.0,
        "target_update.tau": 0.005,
        "alpha_optimizer.lr": 3e-4,
        "loss.target_entropy": "auto",
        "loss.min_alpha": 0.001,
        "loss.max_alpha": 0.1,
        "buffer_size": 1_000_000,
        "expert_ratio": 0.5,
        "random_steps": 5000,
        "total_steps": 2_000_000,
        "critic_scheduler._target_": "torch.optim.lr_scheduler.CosineAnnealingLR",
    },
}
PAPER_SHARED["iq_learn"] = PAPER_SHARED["sqil"]
# The per-family entries of tab:hparams (A = AntMaze, H = HumanoidMaze).
PAPER_FAMILY = {
    "antmaze_medium": {
        "k": 10,
        "utd_ratio": 0.25,
        "ppo_epochs": 4,
        "episodes_per_round": 20,
        "rounds": 500,
        "epochs": 100,
        "patience": 15,
        "num_value_samples": 16,
        "horizon": 1000,
    },
    "antmaze_large": {
        "k": 10,
        "utd_ratio": 0.25,
        "ppo_epochs": 4,
        "episodes_per_round": 20,
        "rounds": 500,
        "epochs": 100,
        "patience": 15,
        "num_value_samples": 16,
        "horizon": 1000,
    },
    "humanoidmaze_medium": {
        "k": 2,
        "utd_ratio": 0.5,
        "ppo_epochs": 2,
        "episodes_per_round": 10,
        "rounds": 200,
        "epochs": 100,
        "patience": 30,
        "num_value_samples": 1,
        "horizon": 2000,
    },
    "humanoidmaze_large": {
        "k": 2,
        "utd_ratio": 0.5,
        "ppo_epochs": 2,
        "episodes_per_round": 10,
        "rounds": 200,
        "epochs": 200,
        "patience": 15,
        "num_value_samples": 1,
        "horizon": 2000,
    },
}
FAMILY_KEYS = {
    "bc": ("epochs", "patience"),
    "gail": ("ppo_epochs", "episodes_per_round", "rounds"),
    "sqil": ("utd_ratio",),
    "iq_learn": ("utd_ratio", "loss.num_value_samples"),
}


GROUPS = {group: sorted(p.stem for p in (CONFIG_DIR / group).glob("*.yaml")) for group in ("env", "algo", "window", "logger", "scale")}


def _targets(node: Any, where: str = "") -> Iterator[tuple[str, str]]:
    if isinstance(node, Mapping):
        if "_target_" in node:
            yield where, node["_target_"]
        for key, value in node.items():
            yield from _targets(value, f"{where}.{key}" if where else str(key))


def test_groups_are_the_expected_ones() -> None:
    assert GROUPS["env"] == sorted(ENVS) and GROUPS["algo"] == sorted(ALGOS)
    assert GROUPS["window"] == ["default", "matched"] and GROUPS["scale"] == ["cpu", "cpu_ant", "paper"]
    assert GROUPS["logger"] == ["csv", "tensorboard", "wandb"]


@pytest.mark.parametrize("env", GROUPS["env"])
def test_every_group_combination_composes_validates_and_resolves_its_targets(env: str) -> None:
    """env x algo x scale in full (``algo_scale`` depends on the algo and scale pair);
    window and logger, which interact with nothing but ``${env.paper.window_k}``, take each of
    their two options with every env and every algo."""
    for index, (algo, scale) in enumerate(itertools.product(GROUPS["algo"], GROUPS["scale"])):
        window = GROUPS["window"][index % 2]
        logger = GROUPS["logger"][(index % 2 + index // 2) % 2]  # each algo gets both windows and both loggers
        causal = window != "matched"  # the window-matched baseline is non-causal by definition
        cfg = compose_config(
            [f"env={env}", f"algo={algo}", f"window={window}", f"logger={logger}", f"scale={scale}", f"causal={causal}", "seed=4"]
        )
        resolved = OmegaConf.to_container(cfg, resolve=True, enum_to_str=True)
        assert resolved["env"]["expert"] is not None  # every env ships its expert (HumanoidMaze's since issue 38)
        validate_config(cfg)
        assert resolved["env"]["name"] == env and resolved["algo"]["name"] == algo
        assert resolved["run_dir"] == f"runs/{cfg.run_name}"
        assert cfg.run_name.endswith(f"/{run_label(algo, causal, window == 'matched')}/seed4")
        trainer = resolved["algo"]["trainer"]
        assert (trainer is None) == (algo == "expert")
        if trainer is not None:
            assert issubclass(get_class(trainer), Trainer)
        targets = dict(_targets(resolved))
        assert {"env.make", "logger"} <= set(targets) and ("env.expert" in targets) == (resolved["env"]["expert"] is not None)
        for where, target in targets.items():
            assert callable(get_object(target)), (env, algo, where, target)


def test_networks_and_losses_instantiate_from_the_config() -> None:
    from torchrl.data import Bounded

    spec = Bounded(-1.0, 1.0, shape=(2,))
    for algo in ("bc", "gail", "sqil", "iq_learn"):
        cfg = compose_config([f"algo={algo}", "scale=cpu"]).algo
        actor = instantiate(cfg.actor)(5, spec)
        assert sum(p.numel() for p in actor.parameters()) > 0
        if algo in ("sqil", "iq_learn"):
            loss = instantiate(cfg.loss)(actor, instantiate(cfg.critic)(5, spec))
            assert type(loss).__name__ == {"sqil": "SQILLoss", "iq_learn": "IQLearnLoss"}[algo]
            assert getattr(loss, "num_value_samples", 16) == 16


@pytest.mark.parametrize(
    ("override", "exception", "named"),
    [
        ("causal=maybe", ConfigCompositionException, "causal"),
        ("seed=abc", ConfigCompositionException, "seed"),
        ("window.mode=fuzzy", ConfigCompositionException, "exact, relaxed"),
        ("algo.batch_size=many", ConfigCompositionException, "algo.batch_size"),
        ("algo.unknown_key=1", ConfigCompositionException, "algo.unknown_key"),
        ("env=atlantis", MissingConfigException, "rovermaze_u"),
    ],
)
def test_a_value_of_the_wrong_type_fails_at_composition(override: str, exception: type, named: str) -> None:
    with pytest.raises(exception) as error:
        compose_config([override])
    message = str(error.value) + "".join(str(cause) for cause in (error.value.__cause__, error.value.__context__) if cause)
    assert named in message


@pytest.mark.parametrize(
    "override",
    [
        "episodes=0",
        "eval.episodes=0",
        "eval.final_episodes=0",
        "eval.num_envs=0",
        "demos.episodes=0",
        "algo.num_envs=0",
        "algo.batch_size=1",
        "algo.expert_ratio=1.0",
        "algo.actor.dropout=1.0",
        "env.confounding_strength=1.5",
        "env.confounding_strength=-0.1",
        "env.horizon=0",
        "window.k=-1",
        "threads=0",
        "algo.loss.target_entropy=high",
        "log_every=0",
        "collector_workers=0",
        "collector_workers=3",
        "algo.random_steps=5001",
        "device=cuda:999",
        "device=gpu",
        "window.k=1000",
        "algo.total_steps=5000",
        "max_memory_gb=0",
    ],
)
def test_an_out_of_range_value_is_refused_by_name(override: str) -> None:
    key = override.split("=")[0]
    if key == "episodes":  # not a key: Hydra refuses it outright
        with pytest.raises(ConfigCompositionException):
            compose_config([override])
        return
    with pytest.raises(ConfigValueError, match=key.replace(".", r"\.")):
        validate_config(compose_config([override]))


@pytest.mark.parametrize(
    "override, named, hint",
    [
        ("+windw.k=2", "windw.k", "window.k"),  # Hydra's own suggestion for the typo windw.k=2
        ("+window.lags=3", "window.lags", None),
        ("+algo.actor.hiden=3", "algo.actor.hiden", "algo.actor.hidden"),
        ("+eval.episode=3", "eval.episode", "eval.episodes"),
    ],
)
def test_a_key_added_with_plus_is_refused_like_an_unknown_key(override: str, named: str, hint: str | None) -> None:
    cfg = compose_config(["algo=sqil", override])  # `+` gets past composition ...
    with pytest.raises(ConfigValueError, match=rf"config key {re.escape(named)} is unknown") as error:
        validate_config(cfg)  # ... and is refused before anything runs
    assert hint is None or f"did you mean {hint}?" in str(error.value)


def test_free_form_target_arguments_take_added_keys() -> None:
    # env.make's keys are the env class's keyword arguments: no schema lists them
    validate_config(compose_config(["env=rovermaze_u", "+env.make.extra=1"]))


def test_sizes_must_agree_and_a_budget_must_outlast_the_warm_up() -> None:
    validate_config(compose_config(["env=rovermaze_u", "env.horizon=40", "window.k=39"]))
    with pytest.raises(ConfigValueError, match=r"window\.k=40 must be < env\.horizon=40"):
        validate_config(compose_config(["env=rovermaze_u", "env.horizon=40", "window.k=40"]))
    validate_config(compose_config(["env=route_choice"]))  # one stage, k = 0
    with pytest.raises(ConfigValueError, match=r"algo\.total_steps=100 must be > algo\.random_steps=512"):
        validate_config(compose_config(["algo=sqil", "algo.total_steps=100", "algo.random_steps=512"]))
    validate_config(compose_config(["algo=sqil", "algo.total_steps=520", "algo.random_steps=512"]))


def test_enums_of_the_losses_name_their_options() -> None:
    for algo, override, options in (
        ("iq_learn", "algo.loss.variant=online", "paper, iq_learn"),
        ("gail", "algo.loss.reward=negative", "logit, positive"),
    ):
        with pytest.raises(ConfigCompositionException) as error:
            compose_config([f"algo={algo}", override])
        assert options in str(error.value.__cause__)
    assert compose_config(["algo=gail", "algo.loss.reward=positive"]).algo.loss.reward == "positive"


def test_off_policy_counts_must_divide_and_gail_has_no_actor_dropout() -> None:
    with pytest.raises(ConfigValueError, match=r"collector_workers=3 must divide algo\.num_envs=8"):
        validate_config(compose_config(["collector_workers=3"]))
    validate_config(compose_config(["collector_workers=4"]))
    with pytest.raises(ConfigValueError, match=r"algo\.random_steps=5001 must be a multiple of algo\.frames_per_batch=8"):
        validate_config(compose_config(["algo.random_steps=5001"]))
    with pytest.raises(ConfigValueError, match=r"algo\.actor\.dropout must be 0 for GAIL"):
        validate_config(compose_config(["algo=gail", "algo.actor.dropout=0.05"]))
    validate_config(compose_config(["algo=sqil", "algo.actor.dropout=0.05"]))  # SQIL's actor keeps Appendix E's


def test_booleans_are_booleans() -> None:
    assert compose_config(["causal=false"]).causal is False
    assert compose_config(["causal=no"]).causal is False  # YAML 1.1 spelling, converted, never a string
    assert compose_config(["causal=true"]).causal is True


@pytest.mark.parametrize("env", sorted(PAPER_FAMILY))
def test_scale_paper_is_appendix_e(env: str) -> None:
    facts = PAPER_FAMILY[env]
    for algo, shared in PAPER_SHARED.items():
        cfg = compose_config([f"env={env}", f"algo={algo}", "scale=paper"])
        for key, value in shared.items():
            assert OmegaConf.select(cfg.algo, key) == value, (env, algo, key)
        for key in FAMILY_KEYS[algo]:
            assert OmegaConf.select(cfg.algo, key) == facts[key.split(".")[-1]], (env, algo, key)
        assert cfg.window.k == facts["k"] and cfg.env.horizon == facts["horizon"]
        assert cfg.eval.final_episodes == 1000


def test_scale_cpu_shrinks_budgets_not_objectives() -> None:
    for algo in ("bc", "gail", "sqil", "iq_learn"):
        paper = compose_config(["env=rovermaze_medium", f"algo={algo}", "scale=paper"]).algo
        cpu = compose_config(["env=rovermaze_medium", f"algo={algo}", "scale=cpu"]).algo
        assert cpu.actor.hidden < paper.actor.hidden
        for key in (
            "value_estimator.gamma",
            "loss.gamma",
            "target_update.tau",
            "loss.min_alpha",
            "loss.max_alpha",
            "expert_ratio",
            "loss.clip_epsilon",
            "loss.gp_lambda",
            "val_fraction",
            "loss.delta",
            "utd_ratio",
            "loss.num_value_samples",
        ):
            assert OmegaConf.select(cpu, key) == OmegaConf.select(paper, key), (algo, key)
    assert compose_config(["algo=sqil"]).algo.total_steps < 2_000_000


def test_overrides_reach_env_window_and_run_dir() -> None:
    cfg = compose_config(
        ["env=rovermaze_large", "algo=iq_learn", "causal=true", "window.k=2", "seed=1", "env.horizon=500", "env.confounding_strength=0.5"]
    )
    assert cfg.run_name == "rovermaze_large/h500-cs0.5-k2/c_iq_learn/seed1"
    assert "h500-cs0.5" in cfg.demos.path
    from torchrl_causal.experiment.builders import make_env

    env = make_env(cfg, "deploy", 2, 0)
    assert (env.horizon, env.confounding_strength, env.regime, env.maze) == (500, 0.5, "deploy", "large")
    matched = compose_config(["window=matched", "causal=false"])
    assert matched.window.window_matched and matched.run_name.split("/")[-2] == "sqil_wm"
    with pytest.raises(InterpolationResolutionError, match="non-causal baseline"):
        compose_config(["window=matched", "causal=true"]).run_name
    no_action = compose_config(["window.drop=[X]"])
    assert no_action.run_name == "rovermaze_medium/h1000-cs1.0-k10/c_sqil_no-X/seed0"
    from torchrl_causal.experiment.builders import make_window

    assert "X" in make_window(compose_config([])).lags and "X" not in make_window(no_action).lags
    with pytest.raises(ValueError, match="cannot drop"):
        make_window(compose_config(["window.drop=[compass]"]))


@pytest.mark.parametrize("env", sorted(ENVS))
@pytest.mark.parametrize("causal", [True, False])
def test_the_run_window_comes_from_the_env_class_without_building_an_env(env: str, causal: bool, monkeypatch) -> None:
    """``make_window`` reads the class's template; the window equals the one built from a live
    env (the transform's own route), and no env is constructed on the way."""
    from torchrl_causal.experiment import builders
    from torchrl_causal.transforms import CausalWindowTransform

    cfg = compose_config([f"env={env}", f"causal={str(causal).lower()}"])
    live = builders.make_env(cfg, "train", 1, 0)
    expected = CausalWindowTransform.from_env(live, cfg.window.k, causal=causal).window
    live.close()

    def no_env(*args: Any, **kwargs: Any) -> None:
        raise AssertionError("make_window built an env")

    monkeypatch.setattr(builders, "make_env", no_env)
    assert builders.make_window(cfg) == expected


@pytest.mark.parametrize(
    ("experiment", "swept"),
    [
        ("paper_table", {"row": "expert,c_bc,c_gail,c_sqil,c_iq_learn,bc,gail,sqil,iq_learn,c_iq_learn_garg,sqil_wm", "seed": "0,1,2"}),
        ("antmaze_table", {"row": "expert,c_bc,c_gail,c_sqil,c_iq_learn,bc,gail,sqil,iq_learn", "seed": "0"}),
        ("window_ablation", {"window.k": "0,1,2,5,10,100", "causal": "true"}),
        ("horizon_ablation", {"env.horizon": "500,1000,1500", "env": "antmaze_medium,antmaze_large"}),
        ("strength_ablation", {"env.confounding_strength": "0.15,0.5,0.85,1.0"}),
        ("antmaze_horizon", {"env.horizon": "500,1500", "env": "antmaze_medium,antmaze_large", "row": "c_bc,bc", "seed": "0"}),
        ("antmaze_strength", {"env.confounding_strength": "0.15,0.5,0.85", "env": "antmaze_medium,antmaze_large", "row": "c_bc,bc"}),
        ("antmaze_shift", {"env": "antmaze_medium", "row": "expert,c_bc,bc", "seed": "0"}),
    ],
)
def test_experiments_sweep_the_papers_grids(experiment: str, swept: dict[str, str]) -> None:
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose(config_name="config", overrides=[f"experiment={experiment}"], return_hydra_config=True)
    params = {k: str(v) for k, v in cfg.hydra.sweeper.params.items()}
    for key, value in swept.items():
        assert params[key].replace(" ", "") == value


ROWS = [row.name for row in REGISTERED_ROWS]


def test_the_registry_names_every_algo_option_with_the_schema_that_types_it() -> None:
    assert sorted(entry.name for entry in ALGORITHMS) == GROUPS["algo"]
    assert {entry.schema for entry in ALGORITHMS} == set(ALGO_SCHEMAS)
    for entry in ALGORITHMS:
        cfg = compose_config([f"algo={entry.name}"])
        assert cfg.algo.name == entry.name
        assert OmegaConf.get_type(cfg.algo) is ALGO_SCHEMAS[entry.schema] is algo_schema(entry.name)
    assert algo_schema("not_registered") is AlgoConfig


@pytest.mark.parametrize("row", ROWS)
def test_each_table_row_is_the_run_it_names(row: str) -> None:
    cfg = compose_config(["experiment=paper_table", f"row={row}", "env=rovermaze_medium"])
    assert cfg.run_name.split("/")[-2] == row
    registered = Row.parse(row)
    assert (cfg.causal, cfg.window.window_matched) == (registered.causal, registered.window_matched)
    assert cfg.algo.name == row.removeprefix("c_").removesuffix("_wm")
    if row.endswith("iq_learn_garg"):
        assert cfg.algo.loss.variant == "iq_learn"
        assert cfg.algo.actor_optimizer.lr == 3e-5  # Garg et al.'s online commands (actor_lr)
    elif row.endswith("iq_learn"):
        assert cfg.algo.loss.variant == "paper"


def test_entry_point_composes_from_any_directory(tmp_path) -> None:
    out = subprocess.run(
        [sys.executable, "-m", "torchrl_causal.train", "env=route_choice", "algo=gail", "--cfg", "job", "--resolve"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    cfg = OmegaConf.create(out.stdout)
    assert cfg.algo.name == "gail" and cfg.env.name == "route_choice" and cfg.window.k == 0


def test_the_demo_runs_validate(tmp_path) -> None:
    from torchrl_causal.cli.demo import DEMO_RUNS, demo_overrides

    # the main job shows the paper's method against its twin, and BC against C-BC
    assert {("sqil", True), ("sqil", False), ("bc", True), ("bc", False)} <= set(DEMO_RUNS)
    assert DEMO_RUNS[0] == ("expert", False)  # its demonstrations feed the others
    for algo, causal in DEMO_RUNS:
        validate_config(compose_config(demo_overrides(algo, causal, tmp_path)))


def test_an_env_without_an_expert_is_refused_with_how_to_name_one() -> None:
    cfg = compose_config(["env=humanoidmaze_medium", "algo=bc", "env.expert=null"])
    with pytest.raises(ConfigValueError, match=r"'humanoidmaze_medium' has no expert .*HumanoidMazeExpert, weights: PATH"):
        validate_config(cfg)
