"""The Hydra config tree: every env x algo composes, scale=paper is Appendix E exactly,
overrides reach the run, experiments sweep what the paper sweeps."""

from __future__ import annotations

import subprocess
import sys

import pytest
from hydra.utils import instantiate
from omegaconf import OmegaConf
from omegaconf.errors import InterpolationResolutionError

from torchrl_causal.trainers import CONFIG_DIR, TRAINERS, compose_config, run_label

ENVS = ("rovermaze_u", "rovermaze_medium", "rovermaze_large", "route_choice",
        "antmaze_medium", "antmaze_large", "humanoidmaze_medium", "humanoidmaze_large")
ALGOS = ("bc", "gail", "sqil", "iq_learn", "iq_learn_garg", "expert")

# Appendix E, tab:hparams, transcribed: (key in the algo config, value) per algorithm,
# shared by both environment families.
PAPER_SHARED = {
    "bc": {"actor.hidden": 256, "actor.blocks": 4, "actor.dropout": 0.0, "lr": 3e-4, "batch_size": 2048,
           "val_fraction": 0.2},
    "gail": {"actor.hidden": 256, "actor.blocks": 3, "actor.dropout": 0.0,  # 0.05 in the paper: see gail.yaml
             "lr_actor": 1e-4, "lr_critic": 3e-4,
             "batch_size": 1024, "gamma": 0.99, "max_grad_norm": 0.5, "clip_epsilon": 0.2, "gae_lambda": 0.95,
             "entropy_coef": 1e-2, "critic_coef": 0.5, "normalize_advantage": True, "lr_discriminator": 3e-4,
             "discriminator.dropout": 0.2, "discriminator_updates": 2, "discriminator_batch_size": 1024,
             "gradient_penalty": 5.0, "discriminator_lr_step": 100, "discriminator_lr_gamma": 0.5},
    "sqil": {"actor.hidden": 256, "actor.blocks": 3, "actor.dropout": 0.05, "critic.hidden": 256, "critic.blocks": 3,
             "lr_actor": 3e-4, "lr_critic": 3e-4, "batch_size": 256, "gamma": 0.99, "max_grad_norm": 1.0,
             "tau": 0.005, "lr_alpha": 3e-4, "target_entropy": "auto", "alpha_min": 0.001, "alpha_max": 0.1,
             "buffer_size": 1_000_000, "expert_ratio": 0.5, "random_steps": 5000, "total_steps": 2_000_000,
             "critic_lr_schedule": "cosine"},
}
PAPER_SHARED["iq_learn"] = PAPER_SHARED["sqil"]
# The per-family entries of tab:hparams (A = AntMaze, H = HumanoidMaze).
PAPER_FAMILY = {
    "antmaze_medium": {"k": 10, "utd_ratio": 0.25, "ppo_epochs": 4, "episodes_per_round": 20, "rounds": 500,
                       "epochs": 100, "patience": 15, "value_samples": 16, "horizon": 1000},
    "antmaze_large": {"k": 10, "utd_ratio": 0.25, "ppo_epochs": 4, "episodes_per_round": 20, "rounds": 500,
                      "epochs": 100, "patience": 15, "value_samples": 16, "horizon": 1000},
    "humanoidmaze_medium": {"k": 2, "utd_ratio": 0.5, "ppo_epochs": 2, "episodes_per_round": 10, "rounds": 200,
                            "epochs": 100, "patience": 30, "value_samples": 1, "horizon": 2000},
    "humanoidmaze_large": {"k": 2, "utd_ratio": 0.5, "ppo_epochs": 2, "episodes_per_round": 10, "rounds": 200,
                           "epochs": 200, "patience": 15, "value_samples": 1, "horizon": 2000},
}
FAMILY_KEYS = {"bc": ("epochs", "patience"), "gail": ("ppo_epochs", "episodes_per_round", "rounds"),
               "sqil": ("utd_ratio",), "iq_learn": ("utd_ratio", "value_samples")}


@pytest.mark.parametrize("env", ENVS)
def test_every_env_and_algo_composes(env: str) -> None:
    for algo in ALGOS:
        for scale in ("cpu", "paper"):
            cfg = compose_config([f"env={env}", f"algo={algo}", f"scale={scale}", "causal=false", "seed=4"])
            resolved = OmegaConf.to_container(cfg, resolve=True)  # every interpolation resolves
            assert resolved["algo"]["trainer"] in TRAINERS
            assert resolved["env"]["name"] == env
            assert resolved["run_dir"] == f"runs/{cfg.run_name}"
            assert cfg.run_name.endswith(f"/{run_label(algo, False)}/seed4")


@pytest.mark.parametrize("env", sorted(PAPER_FAMILY))
def test_scale_paper_is_appendix_e(env: str) -> None:
    facts = PAPER_FAMILY[env]
    for algo, shared in PAPER_SHARED.items():
        cfg = compose_config([f"env={env}", f"algo={algo}", "scale=paper"])
        for key, value in shared.items():
            assert OmegaConf.select(cfg.algo, key) == value, (env, algo, key)
        for key in FAMILY_KEYS[algo]:
            assert cfg.algo[key] == facts[key], (env, algo, key)
        assert cfg.window.k == facts["k"] and cfg.env.horizon == facts["horizon"]
        assert cfg.eval.final_episodes == 1000


def test_scale_cpu_shrinks_budgets_not_objectives() -> None:
    for algo in ("bc", "gail", "sqil", "iq_learn"):
        paper = compose_config(["env=rovermaze_medium", f"algo={algo}", "scale=paper"]).algo
        cpu = compose_config(["env=rovermaze_medium", f"algo={algo}", "scale=cpu"]).algo
        assert cpu.actor.hidden < paper.actor.hidden
        for key in ("gamma", "tau", "alpha_min", "alpha_max", "expert_ratio", "clip_epsilon", "gradient_penalty",
                    "val_fraction", "huber_delta", "utd_ratio", "value_samples"):
            assert OmegaConf.select(cpu, key) == OmegaConf.select(paper, key), (algo, key)
    assert compose_config(["algo=sqil"]).algo.total_steps < 2_000_000


def test_overrides_reach_env_window_and_run_dir() -> None:
    cfg = compose_config(["env=rovermaze_large", "algo=iq_learn", "causal=true", "window.k=2", "seed=1",
                          "env.horizon=500", "env.confounding_strength=0.5"])
    assert cfg.run_name == "rovermaze_large/h500-cs0.5-k2/c_iq_learn/seed1"
    assert "h500-cs0.5" in cfg.demos.path
    env = instantiate(cfg.env.make, regime="deploy", batch_size=(2,), horizon=cfg.env.horizon,
                      confounding_strength=cfg.env.confounding_strength, seed=0)
    assert (env.horizon, env.confounding_strength, env.regime, env.maze) == (500, 0.5, "deploy", "large")
    matched = compose_config(["window=matched", "causal=false"])
    assert matched.window.window_matched and matched.run_name.split("/")[-2] == "sqil_wm"
    with pytest.raises(InterpolationResolutionError, match="non-causal baseline"):
        compose_config(["window=matched", "causal=true"]).run_name


@pytest.mark.parametrize(
    ("experiment", "swept"),
    [
        ("paper_table", {"row": "expert,c_bc,c_gail,c_sqil,c_iq_learn,c_iq_learn_garg,bc,gail,sqil,iq_learn,sqil_wm",
                         "seed": "0,1,2"}),
        ("window_ablation", {"window.k": "0,1,2,5,10,100", "causal": "true"}),
        ("horizon_ablation", {"env.horizon": "500,1000,1500", "env": "antmaze_medium,antmaze_large"}),
        ("strength_ablation", {"env.confounding_strength": "0.15,0.5,0.85,1.0"}),
    ],
)
def test_experiments_sweep_the_papers_grids(experiment: str, swept: dict[str, str]) -> None:
    from hydra import compose, initialize_config_dir

    from torchrl_causal.trainers.config import CONFIG_DIR

    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose(config_name="config", overrides=[f"experiment={experiment}"], return_hydra_config=True)
    params = {k: str(v) for k, v in cfg.hydra.sweeper.params.items()}
    for key, value in swept.items():
        assert params[key].replace(" ", "") == value


ROWS = sorted(path.stem for path in (CONFIG_DIR / "row").glob("*.yaml"))


@pytest.mark.parametrize("row", ROWS)
def test_each_table_row_is_the_run_it_names(row: str) -> None:
    cfg = compose_config(["experiment=paper_table", f"row={row}", "env=rovermaze_medium"])
    assert cfg.run_name.split("/")[-2] == row
    assert cfg.algo.name == row.removeprefix("c_").removesuffix("_wm")
    if row.endswith("iq_learn_garg"):
        assert cfg.algo.variant == "iq_learn"
    elif row.endswith("iq_learn"):
        assert cfg.algo.variant == "paper"


def test_entry_point_composes_from_any_directory(tmp_path) -> None:
    out = subprocess.run(
        [sys.executable, "-m", "torchrl_causal.train", "env=route_choice", "algo=gail", "--cfg", "job", "--resolve"],
        cwd=tmp_path, capture_output=True, text=True, timeout=120,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    cfg = OmegaConf.create(out.stdout)
    assert cfg.algo.name == "gail" and cfg.env.name == "route_choice" and cfg.window.k == 0
