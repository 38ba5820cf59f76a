"""The paper's humanoid: our HumanoidMaze against OGBench's own ``humanoidmaze`` env.

The reference is the installed ``ogbench`` package's env (env only: no dataset is read), built
by its own maze factory around its own ``humanoid.xml``. OGBench lays its maze out in another
frame (cell ``(i, j)`` at ``(4 j - 4, 4 i - 4)``; gymnasium-robotics': ``y`` mirrored and
centred), so the trajectory checks put both humanoids at the same world point, 2.5 m from every
wall of both mazes: contact dynamics are chaotic, and the rounding of positions translated by
a few metres alone drifts a random-action trajectory apart by 1e-3 within 200 steps.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import ogbench
import pytest
import torch
from ogbench.online_locomotion.humanoid import tolerance  # OGBench's skill reward parts
from tensordict import TensorDict

from torchrl_causal.envs import GustProcess, HumanoidMazeEnv
from torchrl_causal.envs.humanoid import HumanoidLocomotionEnv

#: A world point 2.5 m from every wall of OGBench's medium maze and of ours.
CLEAR_POINT = np.array([1.5, 2.0])
STEPS = 300


def _ogbench_medium():
    env = ogbench.make_env_and_datasets("humanoidmaze-medium-navigate-v0", env_only=True)
    return env.unwrapped


def _ours(seed: int = 0) -> HumanoidMazeEnv:
    env = HumanoidMazeEnv("medium", batch_size=1, seed=seed)
    env.gust_process = GustProcess(probability=0.0)  # no tremor: OGBench has none
    return env


def _ogbench_observation(ours: dict[str, torch.Tensor]) -> torch.Tensor:
    """Our variables in the order of OGBench's ``HumanoidEnv.get_ob`` (69 dims)."""
    keys = ("P", "A", "H", "E", "V", ("latent", "C"), "J")
    return torch.cat([ours[key] for key in keys], dim=-1)


def test_our_model_is_ogbench_humanoid_in_ogbench_maze():
    reference, ours = _ogbench_medium().model, _ours().simulator.model
    for option in ("timestep", "integrator", "iterations", "tolerance", "cone", "solver", "jacobian"):
        assert getattr(ours.opt, option) == getattr(reference.opt, option), option
    assert ours.opt.timestep == 0.005 and ours.opt.iterations == 100
    for field in (
        "jnt_range",
        "jnt_stiffness",
        "dof_damping",
        "dof_armature",
        "actuator_gear",
        "actuator_ctrlrange",
        "body_mass",
        "body_inertia",
        "body_pos",
        "body_quat",
        "qpos0",
    ):
        np.testing.assert_array_equal(getattr(ours, field), getattr(reference, field), err_msg=field)

    # The humanoid's geoms (contact, friction, shape) are OGBench's, then come the walls.
    def body_geoms(model):
        ids = np.flatnonzero(model.geom_bodyid > 0)
        return {
            field: getattr(model, field)[ids]
            for field in (
                "geom_size",
                "geom_pos",
                "geom_contype",
                "geom_conaffinity",
                "geom_condim",
                "geom_friction",
                "geom_solref",
                "geom_solimp",
            )
        }

    for field, value in body_geoms(reference).items():
        np.testing.assert_array_equal(body_geoms(ours)[field], value, err_msg=field)
    # Walls: the same boxes (4 m cells, 2 m high, default contact) in OGBench's frame.
    rows, cols = 8, 8

    def walls(model, to_ogbench):
        boxes = []
        for geom in range(model.ngeom):
            if model.geom(geom).name.startswith("block_"):
                x, y, z = model.geom_pos[geom]
                boxes.append(
                    (
                        *to_ogbench(x, y),
                        z,
                        *model.geom_size[geom],
                        *model.geom_solref[geom],
                        *model.geom_friction[geom],
                        model.geom_contype[geom],
                        model.geom_conaffinity[geom],
                    )
                )
        return sorted(np.round(boxes, 9).tolist())

    ours_in_ogbench_frame = walls(ours, lambda x, y: (x + 2 * cols - 6, 2 * rows - 6 - y))
    assert ours_in_ogbench_frame == walls(reference, lambda x, y: (x, y))
    assert len(ours_in_ogbench_frame) == sum(map(sum, HumanoidMazeEnv.tasks["medium"].maze_map))


def _start_from(reference, ours: HumanoidMazeEnv, qpos: np.ndarray, qvel: np.ndarray):
    """Puts both humanoids in state ``(qpos, qvel)`` at :data:`CLEAR_POINT`; our reset tensordict."""
    qpos = qpos.copy()
    qpos[:2] = CLEAR_POINT
    reference.set_state(qpos, qvel)
    td = ours.reset()
    ours.simulator.reset(np.array([0]), qpos[None], qvel[None])  # the variables are read after each step
    return td


def _wall_contacts(model, data) -> int:
    names = [model.geom(data.contact.geom[k, i]).name for k in range(data.ncon) for i in range(2)]
    return sum(name.startswith("block_") for name in names)


@pytest.mark.parametrize("start", ["ogbench_reset", "our_standing_start"])
def test_trajectories_match_ogbench_step_for_step(start):
    reference, ours = _ogbench_medium(), _ours(seed=3)
    if start == "ogbench_reset":  # OGBench's own start: dropped from 1.5 m, random orientation and joints
        reference.reset(seed=3, options={"task_id": 1})
        qpos, qvel = reference.data.qpos.copy(), reference.data.qvel.copy()
    else:
        ours.reset()
        qpos, qvel = ours.simulator.qpos()[0], ours.simulator.qvel()[0]
    td = _start_from(reference, ours, qpos, qvel)
    generator = torch.Generator().manual_seed(7)
    for step in range(STEPS):
        action = 2 * torch.rand(1, 21, generator=generator) - 1
        observation, *_ = reference.step(action[0].double().numpy())
        td["action"] = action
        td = ours.step(td)["next"]
        data = ours.simulator.datas[0]
        # the float64 physics state: the same to rounding after hundreds of contact-rich steps
        gap = max(np.abs(data.qpos - reference.data.qpos).max(), np.abs(data.qvel - reference.data.qvel).max())
        assert gap < 1e-9, (step, gap)
        # what the env emits (float32) is OGBench's observation
        torch.testing.assert_close(_ogbench_observation(td)[0], torch.as_tensor(observation, dtype=torch.float32), rtol=1e-5, atol=1e-4)
        assert _wall_contacts(reference.model, reference.data) == 0 and _wall_contacts(ours.simulator.model, data) == 0
    assert reference.data.ncon > 0  # it was on the floor, not in free flight


# -- the walking skill's open-ground task -----------------------------------------------------


def test_skill_observation_is_ogbench_skill_observation():
    env = HumanoidLocomotionEnv(batch_size=2, seed=0)
    td = env.rollout(20, break_when_any_done=False)[:, -1]["next"]
    reference = _ogbench_medium()
    for index, data in enumerate(env.simulation.datas):
        reference.set_state(data.qpos.copy(), data.qvel.copy())
        expected = torch.as_tensor(reference.get_ob()[2:], dtype=torch.float32)  # OGBench's skill input: no xy
        torch.testing.assert_close(td["observation"][index, :67], expected, rtol=1e-5, atol=1e-5)
        torch.testing.assert_close(td["observation"][index, 67:], td["direction"][index])


@pytest.mark.parametrize("speed_weight", [1.0, 2.5])
def test_skill_reward_is_stand_times_capped_speed_and_a_low_head_ends_it(speed_weight):
    env = HumanoidLocomotionEnv(batch_size=1, speed_cap=0.05, speed_weight=speed_weight, gust_process=GustProcess(probability=0.0), seed=1)
    model = env.simulation.model
    head, torso = model.body("head").id, model.body("torso").id
    generator = torch.Generator().manual_seed(2)
    td = env.reset()
    capped = 0
    for step in range(200):
        td["action"] = 2 * torch.rand(1, 21, generator=generator) - 1
        before = env.simulation.qpos()[0, :2]
        td = env.step(td)["next"]
        data = env.simulation.datas[0]
        mujoco.mj_kinematics(model, data)  # body poses of the state after the step
        speed = float((data.qpos[:2] - before) @ td["direction"][0].double().numpy()) / 0.025
        stand = tolerance(data.xpos[head, 2], bounds=(1.4, float("inf")), margin=0.35) * tolerance(
            data.xmat[torso][8], bounds=(0.9, float("inf")), margin=1.9, sigmoid="linear", value_at_margin=0
        )
        assert td["speed"].item() == pytest.approx(speed, abs=1e-4)
        assert td["reward"].item() == pytest.approx(stand * (1 + speed_weight * min(speed, 0.05)), abs=1e-4)
        capped += speed > 0.05
        assert td["terminated"].item() == (data.xpos[head, 2] < 0.9)
        if td["terminated"].item():
            break
    assert 10 < step < 199 and capped > 0  # it stood a while, walked past the cap once, then fell


def test_skill_commands_are_redrawn_within_the_period_range():
    env = HumanoidLocomotionEnv(batch_size=4, direction_period=(3, 5), gust_process=GustProcess(probability=0.0), seed=0)
    slack = lambda td: td.set("action", torch.zeros(4, 21))  # noqa: E731  (it takes ~35 steps to fall)
    rollout = env.rollout(30, slack, break_when_any_done=False)
    assert not rollout["next", "done"].any()  # no fall yet: a reset would redraw the command too
    direction = rollout["direction"]
    changes = [(direction[k, 1:] != direction[k, :-1]).any(-1).nonzero().flatten() for k in range(4)]
    gaps = torch.cat([torch.diff(torch.cat((torch.tensor([-1]), c))) for c in changes])
    assert gaps.min() >= 3 and gaps.max() <= 5 and len(gaps.unique()) > 1


@pytest.mark.parametrize("spread", [0.0, 0.5])
def test_commands_lie_within_the_spread_of_the_torso_heading_at_each_draw(spread):
    env = HumanoidLocomotionEnv(
        batch_size=3, direction_period=(3, 5), command_spread=spread, gust_process=GustProcess(probability=0.0), seed=4
    )
    model = env.simulation.model
    torso = model.body("torso").id

    def headings() -> np.ndarray:  # from the torso's rotation matrix, not from the quaternion the env reads
        out = []
        for data in env.simulation.datas:
            mujoco.mj_kinematics(model, data)
            out.append(np.arctan2(data.xmat[torso][3], data.xmat[torso][0]))
        return np.array(out)

    td = env.reset()
    draws = [(td["direction"].numpy(), headings(), np.ones(3, dtype=bool))]
    for _ in range(25):  # zero torques: ~35 steps before a fall, so only redraws change the command
        before = td["direction"].clone()
        td = env.step(td.set("action", torch.zeros(3, 21)))["next"]
        draws.append((td["direction"].numpy(), headings(), (td["direction"] != before).any(-1).numpy()))
    offsets = np.concatenate([np.angle(np.exp(1j * (np.arctan2(d[:, 1], d[:, 0]) - h)))[new] for d, h, new in draws])
    assert len(offsets) > 3 * 5  # the first draws and several redraws
    assert np.abs(offsets).max() <= spread + 1e-5
    if spread > 0:
        assert np.abs(offsets).max() > spread / 2  # drawn within the spread, not pinned to the heading


def test_a_command_spread_outside_zero_to_pi_is_refused():
    with pytest.raises(ValueError, match=r"command_spread must lie in \[0, pi\]"):
        HumanoidLocomotionEnv(batch_size=1, command_spread=4.0)


# -- the shipped walking skill (issue 38: >= 3 m along each of four commands, upright) ----------


def test_the_shipped_skill_walks_three_metres_along_each_of_four_commands_and_rarely_falls():
    # Ten seconds from a standing start facing anywhere, one command held, the tremor on. Each walk
    # is chaotic (float rounding on another CPU moves it), so the check is on rates, not on one
    # trajectory: the skill falls in ~6% of such walks (results/humanoid_locomotion/README.md).
    from torchrl_causal.experts.skills import load_humanoid_locomotion_network

    body = load_humanoid_locomotion_network()  # the package's weights, as the maze expert loads them
    angles = torch.tensor([0.0, math.pi / 2, math.pi, -math.pi / 2]).repeat_interleave(8)  # 8 walks per direction
    command = torch.stack((angles.cos(), angles.sin()), dim=-1)
    env = HumanoidLocomotionEnv(batch_size=len(angles), direction_period=10_000, seed=0)
    td = env.reset(TensorDict(direction=command, batch_size=[len(angles)]))
    start = td["xy"].clone()

    def walk(td):
        return td.set("action", torch.tanh(body(td["observation"])[..., :21]))

    with torch.no_grad():
        rollout = env.rollout(400, walk, tensordict=td, auto_reset=False, break_when_any_done=False)  # 40 Hz
    upright = ~rollout["next", "terminated"].any(1).squeeze(-1)  # the head never below 0.9 m
    along = ((rollout["next", "xy"][:, -1] - start) * command).sum(-1)
    assert (along.reshape(4, 8).median(1).values >= 3.0).all(), along.reshape(4, 8)
    assert upright.float().mean() >= 0.75, upright.reshape(4, 8)


# -- the maze expert's wiring ------------------------------------------------------------------


@pytest.mark.parametrize("command_frame", [None, -math.pi / 2])
def test_maze_expert_steers_the_skill_towards_the_planner_waypoint_and_never_reads_w(tmp_path, command_frame):
    from torchrl_causal.experts import HumanoidMazeExpert, MazePlanner
    from torchrl_causal.experts.skills import humanoid_skill_network

    torch.manual_seed(0)
    skill = humanoid_skill_network(command_frame=command_frame)  # the loader rebuilds the frame from the weights' keys
    torch.save(skill.state_dict(), tmp_path / "skill.pt")
    env = HumanoidMazeEnv("medium", batch_size=3, seed=4)
    expert = HumanoidMazeExpert(env, weights=tmp_path / "skill.pt")
    td = env.reset()
    action = expert(td.clone())["action"]
    # independently: OGBench's skill input (its get_ob without xy), then the unit vector to the waypoint
    reference = _ogbench_medium()
    planner = MazePlanner(env.layout, env.task.goal_cell, lookahead=3, clearance=0.45)  # the humanoid's box
    to_waypoint = planner.waypoint(td["P"]) - td["P"]
    direction = to_waypoint / to_waypoint.norm(dim=-1, keepdim=True)
    for index, data in enumerate(env.simulator.datas):
        reference.set_state(data.qpos.copy(), data.qvel.copy())
        observation = torch.cat((torch.as_tensor(reference.get_ob()[2:], dtype=torch.float32), direction[index]))
        expected = torch.tanh(skill(observation)[:21])
        torch.testing.assert_close(action[index], expected, rtol=1e-4, atol=1e-4)
    shaken = td.clone().set("W", -td["W"])
    torch.testing.assert_close(expert(shaken)["action"], action, rtol=0, atol=0)  # W plays no part


def test_maze_expert_without_trained_weights_names_the_command(tmp_path):
    from torchrl_causal.experts import HumanoidMazeExpert

    with pytest.raises(FileNotFoundError, match="--skill humanoid"):
        HumanoidMazeExpert(HumanoidMazeEnv("medium", batch_size=1, seed=0), weights=tmp_path / "missing.pt")


def test_a_humanoidmaze_run_with_a_skill_body_of_ones_own_collects_trains_and_evaluates(tmp_path):
    # Issue 38's Table-1 rows are one command once a body exists: this one has random weights.
    from torchrl_causal.experiment import compose_config
    from torchrl_causal.experts.skills import make_skill_network
    from torchrl_causal.lifecycle import run

    torch.manual_seed(0)
    torch.save(make_skill_network(69, 21).state_dict(), tmp_path / "skill.pt")
    expert = f"+env.expert={{_target_: torchrl_causal.envs.HumanoidMazeExpert, weights: {tmp_path / 'skill.pt'}}}"
    overrides = ["env=humanoidmaze_medium", "env.horizon=12", f"run_root={tmp_path}", "progress_bar=false", "threads=1"]
    overrides += ["demos.episodes=2", "eval.episodes=2", "eval.num_envs=2", "eval.final_episodes=2", "algo=bc", "causal=true"]
    overrides += ["algo.actor.hidden=16", "algo.actor.num_blocks=1", "algo.epochs=1", "algo.eval_every=1", "algo.batch_size=8"]
    cfg = compose_config([*overrides, expert])
    assert cfg.window.k == 2  # the paper's window for HumanoidMaze (Appendix E)
    result = run(cfg)
    assert set(result) == {"train", "deploy"} and all(r.n_episodes == 2 for r in result.values())
    demonstrations = list((tmp_path / "_demos").iterdir())
    assert len(demonstrations) == 1 and demonstrations[0].name.startswith("humanoidmaze_medium-h12")


# -- the command frame: the skill's observation after turning the world about the vertical -----


@pytest.mark.parametrize("yaw", [0.7, -2.0, math.pi])
def test_turning_the_world_turns_only_the_command_frame_vectors_and_the_frame_undoes_it(yaw):
    from torchrl_causal.envs.humanoid import (
        COMMAND_FRAME_VECTORS,
        HUMANOID_COLUMNS,
        HUMANOID_SKILL_VARIABLES,
        HUMANOID_STATE_WIDTH,
        HUMANOID_XML,
        HumanoidReadout,
        standing_qpos,
    )
    from torchrl_causal.experts.skills import CommandFrame

    model = mujoco.MjModel.from_xml_path(str(HUMANOID_XML))
    readout = HumanoidReadout(model)
    rng = np.random.default_rng(0)
    data = mujoco.MjData(model)
    data.qpos[:] = standing_qpos(model, np.array([0.3]))[0] + 0.05 * rng.uniform(-1, 1, model.nq)
    data.qvel[:] = rng.normal(size=model.nv)
    mujoco.mj_step(model, data, 3)  # a moving, tumbling state
    # The same state in a world turned by yaw: position and the free joint's (world-frame) linear
    # velocity turn, the orientation is pre-multiplied, the local angular velocity and hinges stay.
    turn = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
    turned = mujoco.MjData(model)
    turned.qpos[:], turned.qvel[:] = data.qpos, data.qvel
    turned.qpos[:2], turned.qvel[:2] = turn @ data.qpos[:2], turn @ data.qvel[:2]
    mujoco.mju_mulQuat(turned.qpos[3:7], np.array([math.cos(yaw / 2), 0, 0, math.sin(yaw / 2)]), data.qpos[3:7])

    def observation(state: mujoco.MjData, command: np.ndarray) -> torch.Tensor:
        row = np.zeros(HUMANOID_STATE_WIDTH)
        readout.read(state, row)
        return torch.from_numpy(np.concatenate([row[HUMANOID_COLUMNS[v]] for v in HUMANOID_SKILL_VARIABLES] + [command]))

    command = np.array([math.cos(1.1), math.sin(1.1)])
    before, after = observation(data, command), observation(turned, turn @ command)
    moved = [i + k for i in COMMAND_FRAME_VECTORS for k in (0, 1)]
    kept = [i for i in range(len(before)) if i not in moved]
    torch.testing.assert_close(after[kept], before[kept], rtol=0, atol=1e-8)  # everything else is yaw-free
    for i in COMMAND_FRAME_VECTORS:
        torch.testing.assert_close(after[i : i + 2], torch.from_numpy(turn) @ before[i : i + 2], rtol=0, atol=1e-8)
    frame = CommandFrame().double()
    torch.testing.assert_close(frame(after), frame(before), rtol=0, atol=1e-8)
    assert frame(before)[-2:].tolist() == [1.0, 0.0]
    com = COMMAND_FRAME_VECTORS[0]
    along = float(before[com : com + 2] @ torch.from_numpy(command))
    assert abs(float(frame(before)[com]) - along) < 1e-12  # C's first component is its speed along the command
    # At another angle: the same invariance, the command pointing there, the vectors turned with it.
    aside = CommandFrame(yaw).double()
    torch.testing.assert_close(aside(after), aside(before), rtol=0, atol=1e-8)
    # (the angle is a float32 buffer: its rounding, ~1e-7, shows in what it turns)
    torch.testing.assert_close(aside(before)[-2:], torch.tensor([math.cos(yaw), math.sin(yaw)], dtype=torch.float64), rtol=0, atol=1e-6)
    for i in COMMAND_FRAME_VECTORS:
        torch.testing.assert_close(aside(before)[i : i + 2], torch.from_numpy(turn) @ frame(before)[i : i + 2], rtol=0, atol=1e-6)
