"""The MuJoCo maze machinery shared by Confounded AntMaze and Confounded HumanoidMaze.

:class:`MazeSimulator` builds an agent's MJCF inside a gymnasium-robotics maze layout
(their :func:`~gymnasium_robotics.envs.maze.maze_v4.Maze.make_maze` builder and map
constants) and steps a batch of independent :class:`mujoco.MjData` over one compiled
:class:`mujoco.MjModel`, reading MuJoCo's arrays straight into preallocated numpy buffers.

:class:`MujocoMazeEnv` is the SCM layer on top: a
:class:`~torchrl_causal.envs.base.GustConfoundedEnv` whose gust pushes the agent's torso
through ``MjData.xfrc_applied`` every step it blows, whose sensor ``W`` is read from the
agent's state, and whose reward is the maze suite's ``1{success} - |U_t| (1 + d_t / 25)``
(:meth:`~torchrl_causal.envs.GustConfoundedEnv.maze_reward`; success ends the episode).
A subclass only names its agent (MJCF, frame skip, variables and how to read them).
"""

from __future__ import annotations

import math
import os
import sys
from abc import abstractmethod
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import mujoco
import numpy as np
import torch
from gymnasium_robotics.envs.maze.maze_v4 import Maze
from tensordict.utils import NestedKey
from torchrl.data import Bounded, TensorSpec, Unbounded

from torchrl_causal.available import available_memory
from torchrl_causal.envs.base import EnvArgumentError, GustConfoundedEnv, Regime, Shift, batch_rows, validate_batch_size, validate_shift
from torchrl_causal.envs.maze_layout import MAZE_MAPS, MazeLayout
from torchrl_causal.errors import InvalidValueError, RenderingUnavailable

__all__ = ["MAZE_HEIGHT", "MAZE_SIZE_SCALING", "BatchedSimulation", "MazeSimulator", "MazeTask", "MujocoMazeEnv", "OffscreenRenderer"]

#: Side of one maze cell in metres and wall height in cells (gymnasium-robotics AntMaze).
MAZE_SIZE_SCALING = 4.0
MAZE_HEIGHT = 0.5


@dataclass(frozen=True)
class MazeTask:
    """A fixed navigation task: start and goal cells ``(row, column)`` of a gymnasium-robotics layout.

    Examples:
        >>> task = MazeTask("medium", start_cell=(1, 1), goal_cell=(6, 6))
        >>> task.layout.cell_center(torch.tensor(task.goal_cell)).tolist()
        [10.0, -10.0]
    """

    maze: str
    start_cell: tuple[int, int]
    goal_cell: tuple[int, int]

    def __post_init__(self) -> None:
        if self.maze not in MAZE_MAPS:
            raise InvalidValueError(f"maze must be one of {sorted(MAZE_MAPS)}, got {self.maze!r}")
        for name, cell in (("start_cell", self.start_cell), ("goal_cell", self.goal_cell)):
            if not self.layout.is_free_cell(cell):
                raise InvalidValueError(f"{name} {cell} is not a free cell of the {self.maze!r} maze")

    @property
    def maze_map(self) -> list[list[int]]:
        """The layout grid (rows of cells, 1 = wall)."""
        return MAZE_MAPS[self.maze]

    @property
    def layout(self) -> MazeLayout:
        """The layout at the MuJoCo mazes' scale, for :class:`~torchrl_causal.experts.MazePlanner`."""
        return MazeLayout(self.maze_map, cell_size=MAZE_SIZE_SCALING)


SpecEdit = Callable[[mujoco.MjSpec], None]


def _gl_context_class() -> type:
    """The GL context class for offscreen rendering: ``MUJOCO_GL``'s, else EGL when headless.

    ``mujoco.Renderer`` binds the backend MuJoCo picked when it was first imported, and
    ``torchrl.envs`` imports MuJoCo, usually before anyone could set ``MUJOCO_GL``; on a
    headless Linux machine that default (GLFW) cannot open a context, while EGL can.
    """
    backend = os.environ.get("MUJOCO_GL", "").strip().lower()
    headless = not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    if backend == "osmesa":
        from mujoco.osmesa import GLContext
    elif backend == "egl" or (backend == "" and headless and sys.platform.startswith("linux")):
        from mujoco.egl import GLContext
    else:
        GLContext = mujoco.GLContext
    return GLContext


class OffscreenRenderer:
    """Renders RGB frames of a model's simulations into an offscreen framebuffer.

    Args:
        model: the compiled model.
        width, height: frame size in pixels (at most the model's offscreen buffer,
            ``<visual><global offwidth offheight>``).

    Raises:
        RenderingUnavailable: when no GL context can be created, naming the packages to install.
    """

    def __init__(self, model: mujoco.MjModel, *, width: int, height: int) -> None:
        limit = (model.vis.global_.offwidth, model.vis.global_.offheight)
        if not (0 < width <= limit[0] and 0 < height <= limit[1]):
            raise InvalidValueError(f"frame size {width}x{height} must be positive and at most {limit[0]}x{limit[1]}")
        self.width, self.height = width, height
        try:
            self._context = _gl_context_class()(width, height)
            self._context.make_current()
            self._mjr = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
        except Exception as err:  # ImportError, RuntimeError or mujoco.FatalError, by backend
            raise RenderingUnavailable(
                f"offscreen rendering is unavailable (MUJOCO_GL={os.environ.get('MUJOCO_GL')!r}): {err}. "
                "Headless Linux needs EGL (Debian: libegl1 libegl-mesa0 libgl1-mesa-dri) or "
                "MUJOCO_GL=osmesa (Debian: libosmesa6)."
            ) from err
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._mjr)
        self._scene = mujoco.MjvScene(model, maxgeom=10_000)
        self._option = mujoco.MjvOption()
        self._viewport = mujoco.MjrRect(0, 0, width, height)

    def render(self, model: mujoco.MjModel, data: mujoco.MjData, camera: mujoco.MjvCamera) -> np.ndarray:
        """A ``(height, width, 3)`` uint8 frame of ``data`` seen from ``camera``."""
        self._context.make_current()
        mujoco.mjv_updateScene(model, data, self._option, None, camera, mujoco.mjtCatBit.mjCAT_ALL, self._scene)
        mujoco.mjr_render(self._viewport, self._scene, self._mjr)
        pixels = np.empty((self.height, self.width, 3), dtype=np.uint8)
        mujoco.mjr_readPixels(pixels, None, self._viewport, self._mjr)
        return np.flipud(pixels).copy()  # OpenGL's rows start at the bottom

    def close(self) -> None:
        self._context.make_current()
        self._mjr.free()
        self._context.free()


class BatchedSimulation:
    """A batch of independent MuJoCo simulations of one compiled model.

    Each batch element owns an :class:`mujoco.MjData`; :meth:`step` sets the controls and
    a planar external force on one body, then advances ``frame_skip`` physics steps.

    Args:
        model: the compiled model.
        num_envs: number of independent simulations.
        frame_skip: physics steps per control step.
        pushed_body: the body that :meth:`step`'s external force pushes.

    Examples:
        >>> import gymnasium, pathlib
        >>> ant = pathlib.Path(gymnasium.__file__).parent / "envs/mujoco/assets/ant.xml"
        >>> sim = BatchedSimulation(mujoco.MjModel.from_xml_path(str(ant)), num_envs=2, frame_skip=5)
        >>> sim.reset(np.array([0, 1]), sim.model.qpos0[None].repeat(2, 0), np.zeros((2, sim.model.nv)))
        >>> sim.step(np.zeros((2, sim.model.nu)), np.zeros((2, 2)))
        >>> sim.qpos().shape
        (2, 15)
    """

    def __init__(self, model: mujoco.MjModel, *, num_envs: int, frame_skip: int, pushed_body: str = "torso") -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise EnvArgumentError(f"num_envs must be an int >= 1, got {num_envs!r}")
        if frame_skip < 1:
            raise InvalidValueError(f"frame_skip must be >= 1, got {frame_skip}")
        # Each MjData reserves its buffer and its arena (contacts, constraints, solver
        # scratch); past what the machine has, MuJoCo's own allocation fails mid-way.
        need, available = num_envs * (model.nbuffer + model.narena), available_memory()
        if need > available:
            raise EnvArgumentError(
                f"batch size {num_envs} needs {num_envs} MuJoCo simulations of {(model.nbuffer + model.narena) / 2**20:.1f} MB "
                f"each ({need / 2**30:.1f} GB) and {available / 2**30:.1f} GB are available: use a smaller batch_size"
            )
        self.frame_skip = frame_skip
        self.model = model
        self.datas = [mujoco.MjData(model) for _ in range(num_envs)]
        self.torso_id = model.body(pushed_body).id

    @property
    def num_envs(self) -> int:
        return len(self.datas)

    @property
    def control_dt(self) -> float:
        """Simulated seconds per control step (``frame_skip`` physics steps)."""
        return self.frame_skip * self.model.opt.timestep

    def reset(self, indices: np.ndarray, qpos: np.ndarray, qvel: np.ndarray) -> None:
        """Puts the simulations ``indices`` in state ``(qpos[k], qvel[k])``, at rest otherwise."""
        for k, index in enumerate(indices):
            data = self.datas[index]
            mujoco.mj_resetData(self.model, data)
            data.qpos[:] = qpos[k]
            data.qvel[:] = qvel[k]
            mujoco.mj_forward(self.model, data)

    def step(self, ctrl: np.ndarray, torso_force: np.ndarray, indices: Iterable[int] | None = None) -> None:
        """One control step of the simulations ``indices`` (default: every one): ``ctrl`` is
        ``(n, nu)``, ``torso_force`` ``(n, 2)``, rows of the others ignored.

        The planar force (world frame, newtons) is applied at the pushed body's centre of
        mass during every physics substep; a zero force (calm) clears the previous one.
        The simulations share nothing but the read-only model, so a simulation steps to the
        same state whichever others step with it.
        """
        model, torso, frame_skip = self.model, self.torso_id, self.frame_skip
        for index in range(self.num_envs) if indices is None else indices:
            data = self.datas[index]
            data.ctrl[:] = ctrl[index]
            data.xfrc_applied[torso, :2] = torso_force[index]
            mujoco.mj_step(model, data, nstep=frame_skip)

    def qpos(self) -> np.ndarray:
        """A fresh ``(n, nq)`` copy of the generalised positions."""
        return np.stack([data.qpos for data in self.datas])

    def qvel(self) -> np.ndarray:
        """A fresh ``(n, nv)`` copy of the generalised velocities."""
        return np.stack([data.qvel for data in self.datas])

    def get_state(self) -> np.ndarray:
        """``(n, size)`` integration state of every simulation (``mj_getState``: time,
        positions, velocities, actuator activations, warm start, controls, applied forces)."""
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        state = np.empty((self.num_envs, mujoco.mj_stateSize(self.model, spec)))
        for data, row in zip(self.datas, state):
            mujoco.mj_getState(self.model, data, row, spec)
        return state

    def set_state(self, state: np.ndarray) -> None:
        """Inverse of :meth:`get_state` (``mj_setState``, then ``mj_forward``)."""
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        for data, row in zip(self.datas, np.asarray(state, dtype=np.float64)):
            mujoco.mj_setState(self.model, data, row, spec)
            mujoco.mj_forward(self.model, data)


class MazeSimulator(BatchedSimulation):
    """A batch of MuJoCo simulations of one agent in one maze.

    The MJCF is the agent's model with the maze walls and a goal site added by
    gymnasium-robotics' ``Maze.make_maze``; ``edit_spec`` may adjust it (through
    :class:`mujoco.MjSpec`) before compilation.

    Args:
        agent_xml: path of the agent's MJCF (must contain a body named ``torso_body``).
        task: the maze layout with its start and goal cells.
        num_envs: number of independent simulations.
        frame_skip: physics steps per control step.
        torso_body: the body that external forces push.
        edit_spec: optional in-place edit of the compiled model's :class:`mujoco.MjSpec`.

    Examples:
        >>> import gymnasium, pathlib
        >>> ant = pathlib.Path(gymnasium.__file__).parent / "envs/mujoco/assets/ant.xml"
        >>> sim = MazeSimulator(ant, MazeTask("medium", (1, 1), (6, 6)), num_envs=2, frame_skip=5)
        >>> sim.cell_xy((1, 1)).tolist()
        [-10.0, 10.0]
    """

    def __init__(
        self,
        agent_xml: str | os.PathLike,
        task: MazeTask,
        *,
        num_envs: int,
        frame_skip: int,
        torso_body: str = "torso",
        edit_spec: SpecEdit | None = None,
    ) -> None:
        self.task = task
        self.maze, xml_path = Maze.make_maze(str(agent_xml), task.maze_map, MAZE_SIZE_SCALING, MAZE_HEIGHT)
        try:
            spec = mujoco.MjSpec.from_file(xml_path)
        finally:
            os.remove(xml_path)  # make_maze leaves its temporary MJCF behind
        spec.site("target").pos = [*self.cell_xy(task.goal_cell), MAZE_HEIGHT / 2 * MAZE_SIZE_SCALING]
        if edit_spec is not None:
            edit_spec(spec)
        super().__init__(spec.compile(), num_envs=num_envs, frame_skip=frame_skip, pushed_body=torso_body)
        self._renderer: OffscreenRenderer | None = None

    def cell_xy(self, cell: Sequence[int]) -> np.ndarray:
        """World ``(x, y)`` of a cell's centre."""
        return self.maze.cell_rowcol_to_xy(np.asarray(cell))

    def render(self, index: int, *, width: int, height: int, camera: mujoco.MjvCamera) -> np.ndarray:
        """An RGB frame ``(height, width, 3)`` (uint8) of simulation ``index``, offscreen."""
        if self._renderer is None or (self._renderer.width, self._renderer.height) != (width, height):
            self.close()
            self._renderer = OffscreenRenderer(self.model, width=width, height=height)
        data = self.datas[index]
        mujoco.mj_kinematics(self.model, data)  # mj_step leaves body poses one substep behind qpos
        return self._renderer.render(self.model, data, camera)

    def camera(self, name: str) -> mujoco.MjvCamera:
        """The model's fixed camera ``name`` (e.g. ``"track"`` for the ant, ``"back"`` for the humanoid)."""
        camera_id = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_CAMERA, name)
        if camera_id < 0:
            cameras = [self.model.camera(i).name for i in range(self.model.ncam)]
            raise InvalidValueError(f"camera {name!r} is not in the model; it has {cameras}")
        camera = mujoco.MjvCamera()
        camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        camera.fixedcamid = camera_id
        return camera

    def overview_camera(self) -> mujoco.MjvCamera:
        """A free camera looking straight down on the whole maze."""
        camera = mujoco.MjvCamera()
        camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        camera.lookat[:] = (0.0, 0.0, 0.0)
        camera.elevation = -90.0
        camera.azimuth = 90.0
        extent = max(self.maze.map_length, self.maze.map_width) * MAZE_SIZE_SCALING
        camera.distance = 1.1 * extent / (2 * math.tan(math.radians(self.model.vis.global_.fovy) / 2))
        return camera

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


class MujocoMazeEnv(GustConfoundedEnv):
    """A confounded maze navigation task on a MuJoCo agent (base of the ant and humanoid).

    The state of each batch element is read into one row of a float64 buffer whose column
    ranges are the causal variables (:attr:`variable_columns`); observed variables become
    root keys, :attr:`latent_variables` go under ``("latent", name)``, the gust under
    ``("scm", "U")``. ``W`` is ``read_compass`` of :meth:`_sensor_signal`. The episode
    terminates with success when the torso's ground-plane position is within
    ``success_radius`` of the goal cell's centre.

    Subclasses set the class attributes and implement :meth:`_read_state` and
    :meth:`_sensor_signal` (and :attr:`causal_template`).

    Args:
        maze: ``"medium"`` or ``"large"`` (the fixed task of :attr:`tasks`).
        batch_size: the env's batch shape; one MuJoCo simulation per element.
        regime, confounding_strength, horizon, device, seed: see
            :class:`~torchrl_causal.envs.base.ConfoundedEnv`.
        shift: ``"rotation"`` (default) or ``"prior"``: see
            :class:`~torchrl_causal.envs.base.GustConfoundedEnv`.
        success_radius: goal tolerance in metres.
    """

    #: MJCF of the agent.
    agent_xml: ClassVar[str | os.PathLike]
    #: physics steps per control step.
    frame_skip: ClassVar[int]
    #: variable name -> column range in the state buffer (template variables except X and W).
    variable_columns: ClassVar[Mapping[str, slice]]
    #: width of the state buffer.
    state_width: ClassVar[int]
    #: variables hidden from the imitator (live under ``("latent", name)``).
    latent_variables: ClassVar[tuple[str, ...]]
    #: the fixed task of each layout.
    tasks: ClassVar[Mapping[str, MazeTask]]
    #: uniform start-position noise, as a fraction of a cell (gymnasium-robotics uses 0.25).
    start_noise: ClassVar[float] = 0.25
    #: half-width of the uniform noise on the other initial ``qpos`` entries.
    qpos_noise: ClassVar[float] = 0.0
    #: standard deviation of the Gaussian initial ``qvel``.
    qvel_noise_std: ClassVar[float] = 0.0
    default_success_radius: ClassVar[float] = 0.45
    default_horizon: ClassVar[int] = 1000

    def __init__(
        self,
        maze: str = "medium",
        *,
        batch_size: Sequence[int] | torch.Size | int = (),
        regime: Regime = "train",
        confounding_strength: float = 1.0,
        horizon: int | None = None,
        device: torch.device | str | None = None,
        seed: int | None = None,
        shift: Shift = "rotation",
        success_radius: float | None = None,
    ) -> None:
        validate_shift(shift)  # before the simulator is built
        if maze not in self.tasks:
            raise InvalidValueError(f"maze must be one of {tuple(self.tasks)}, got {maze!r}")
        self.maze = maze
        self.task = self.tasks[maze]
        self.layout = self.task.layout
        self.success_radius = float(self.default_success_radius if success_radius is None else success_radius)
        if not self.success_radius > 0:
            raise InvalidValueError(f"success_radius must be > 0, got {success_radius!r}")
        shape = validate_batch_size(batch_size)
        self.simulator = MazeSimulator(
            self.agent_xml,
            self.task,
            num_envs=math.prod(shape),
            frame_skip=self.frame_skip,
            edit_spec=self._edit_spec,
        )
        model = self.simulator.model
        self._bind_model(model)
        self._goal_xy = self.simulator.cell_xy(self.task.goal_cell)
        self._start_xy = self.simulator.cell_xy(self.task.start_cell)
        self._state = np.zeros((self.simulator.num_envs, self.state_width))
        columns = self.variable_columns.items()
        self._observed_columns = [(name, cols) for name, cols in columns if name not in self.latent_variables]
        self._latent_columns = [(name, cols) for name, cols in columns if name in self.latent_variables]
        self._action_low = torch.as_tensor(model.actuator_ctrlrange[:, 0], dtype=torch.float32)
        self._action_high = torch.as_tensor(model.actuator_ctrlrange[:, 1], dtype=torch.float32)
        super().__init__(
            batch_size=shape,
            regime=regime,
            confounding_strength=confounding_strength,
            horizon=self.default_horizon if horizon is None else horizon,
            device=device,
            seed=seed,
            shift=shift,
        )

    # -- agent hooks ---------------------------------------------------------------------

    @classmethod
    def _edit_spec(cls, spec: mujoco.MjSpec) -> None:
        """Adjusts the agent-in-maze MJCF before compilation; nothing by default."""

    def _bind_model(self, model: mujoco.MjModel) -> None:
        """Looks up what :meth:`_read_state` needs in the compiled model; nothing by default."""

    @abstractmethod
    def _read_state(self, data: mujoco.MjData, row: np.ndarray) -> None:
        """Writes the variables of one simulation into its state-buffer ``row``."""

    @abstractmethod
    def _sensor_signal(self, state: np.ndarray) -> np.ndarray:
        """The true signal ``(n, 2)`` that the sensor ``W`` mixes with the gust, from the state buffer.

        Computed in numpy on the float64 buffer: a handful of tiny torch ops per step
        would cost more than the rest of the SCM layer.
        """

    def _start_state(self, count: int) -> tuple[np.ndarray, np.ndarray]:
        """``(qpos, qvel)`` of ``count`` fresh episodes, drawn from the env's generator.

        By default ``qpos0`` plus uniform noise of :attr:`qpos_noise`, the torso's ground-plane
        position at the start cell's centre plus uniform noise of :attr:`start_noise` cells,
        and Gaussian ``qvel`` of :attr:`qvel_noise_std`.
        """
        model = self.simulator.model
        uniform = torch.rand((count, model.nq + 2), generator=self.rng, dtype=torch.float64).numpy() * 2 - 1
        gaussian = torch.randn((count, model.nv), generator=self.rng, dtype=torch.float64).numpy()
        qpos = self._reference_qpos(count) + self.qpos_noise * uniform[:, : model.nq]
        qpos[:, :2] = self._start_xy + self.start_noise * MAZE_SIZE_SCALING * uniform[:, -2:]
        return qpos, self.qvel_noise_std * gaussian

    def _reference_qpos(self, count: int) -> np.ndarray:
        """The ``(count, nq)`` poses that :meth:`_start_state` adds noise to: ``qpos0`` by default."""
        return np.tile(self.simulator.model.qpos0, (count, 1))

    # -- ConfoundedEnv hooks -------------------------------------------------------------

    def _make_variable_specs(self) -> tuple[TensorSpec, Mapping[NestedKey, TensorSpec]]:
        batch = tuple(self.batch_size)
        shape = (*batch, self._action_low.numel())
        action = Bounded(self._action_low.expand(shape), self._action_high.expand(shape), shape=shape, device=self.device)
        variables: dict[NestedKey, TensorSpec] = {}
        for name, columns in self.variable_columns.items():
            key = ("latent", name) if name in self.latent_variables else name
            variables[key] = Unbounded(shape=(*batch, _width(columns)), device=self.device)
        # tanh bounds each component by 1 before the rotation, so by sqrt(2) after it.
        variables["W"] = Bounded(-math.sqrt(2), math.sqrt(2), shape=(*batch, 2), device=self.device)
        return action, variables

    def _reset_state(self, mask: torch.Tensor) -> None:
        indices = np.flatnonzero(mask.reshape(-1).cpu().numpy())
        if indices.size == 0:
            return
        self.simulator.reset(indices, *self._start_state(indices.size))
        for index in indices:
            self._read_state(self.simulator.datas[index], self._state[index])

    def _transition(self, action: torch.Tensor, live: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        ctrl = action.detach().reshape(self.simulator.num_envs, -1).cpu().numpy()
        force = self.gust.reshape(self.simulator.num_envs, 2).cpu().numpy()
        # A partial step neither simulates nor reads the skipped rows (the physics is the
        # whole cost of a step); their state-buffer rows keep the last reading.
        indices = range(self.simulator.num_envs) if live is None else np.flatnonzero(live.reshape(-1).cpu().numpy())
        self.simulator.step(ctrl, force, indices)
        state, datas = self._state, self.simulator.datas
        for index in indices:
            self._read_state(datas[index], state[index])
        x, y = self.variable_columns["P"].start, self.variable_columns["P"].start + 1
        distance = np.hypot(state[:, x] - self._goal_xy[0], state[:, y] - self._goal_xy[1])
        distance = torch.from_numpy(distance.astype(np.float32)).to(self.device).reshape(*self.batch_size, 1)
        success = distance <= self.success_radius
        # The reward of step t pays for the gust U_t that blew during it.
        return self.maze_reward(success, distance), success

    def _observation(self) -> dict[str, object]:
        state = self._torch(self._state)
        observation: dict[str, object] = {name: state[..., columns] for name, columns in self._observed_columns}
        observation["latent"] = {name: state[..., columns] for name, columns in self._latent_columns}
        observation["W"] = self.read_compass(self._torch(self._sensor_signal(self._state)))
        observation.update(self.scm_observation())
        return observation

    def _torch(self, array: np.ndarray) -> torch.Tensor:
        """A float32 copy of shape ``batch + array.shape[1:]`` on the env's device.

        A copy, so that the state buffer can be overwritten in place at the next step.
        """
        tensor = torch.from_numpy(array.astype(np.float32)).to(self.device)
        return tensor.reshape(*self.batch_size, *array.shape[1:])

    def get_extra_state(self) -> dict[str, Any]:
        """:meth:`ConfoundedEnv.get_extra_state` plus every simulation's physics state and
        the variable buffer read from it."""
        return {
            **super().get_extra_state(),
            "physics": torch.from_numpy(self.simulator.get_state()),
            "variables": torch.from_numpy(self._state.copy()),
        }

    def set_extra_state(self, state: Mapping[str, Any]) -> None:
        super().set_extra_state(state)
        self.simulator.set_state(state["physics"].numpy())
        np.copyto(self._state, state["variables"].numpy())

    # -- public ----------------------------------------------------------------------------

    @property
    def goal_xy(self) -> np.ndarray:
        """World ``(x, y)`` of the goal (the goal cell's centre)."""
        return self._goal_xy.copy()

    @property
    def start_xy(self) -> np.ndarray:
        """World ``(x, y)`` of the start cell's centre (resets add uniform noise to it)."""
        return self._start_xy.copy()

    def config(self) -> dict[str, object]:
        return {**super().config(), "maze": self.maze, "success_radius": self.success_radius}

    def render(self, *, width: int = 320, height: int = 320, camera: str | None = None, rows: Sequence[int] | None = None) -> np.ndarray:
        """RGB frames of every batch element, ``batch + (height, width, 3)`` uint8, offscreen.

        ``camera`` names a camera of the agent's MJCF (e.g. ``"track"`` for the ant,
        ``"back"`` for the humanoid); the default looks straight down on the whole maze.
        ``rows`` (flat batch indices) draws only those simulations, ``(len(rows), height, width, 3)``.
        Drawing reads the simulations' poses and draws no random number.

        Raises:
            RenderingUnavailable: no offscreen GL context opens on this machine.
        """
        index = batch_rows(self.simulator.num_envs, rows)
        view = self.simulator.overview_camera() if camera is None else self.simulator.camera(camera)
        drawn = [self.simulator.render(i, width=width, height=height, camera=view) for i in index]
        frames = np.stack(drawn) if drawn else np.empty((0, height, width, 3), dtype=np.uint8)
        return frames if rows is not None else frames.reshape(*self.batch_size, height, width, 3)

    def close(self, *, raise_if_closed: bool = True) -> None:
        self.simulator.close()
        super().close(raise_if_closed=raise_if_closed)


def _width(columns: slice) -> int:
    return columns.stop - columns.start
