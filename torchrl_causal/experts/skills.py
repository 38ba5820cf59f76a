"""The walking skills' policy bodies: the networks the maze experts steer, and the shipped weights.

A skill's body maps its open-ground observation (:mod:`torchrl_causal.envs.open_ground`: the
agent's variables and a commanded unit direction) to the tanh-Gaussian's pre-tanh mean and
log-std (:func:`make_skill_network`); the experts act with ``tanh`` of the mean. The package ships
the ant's body (:data:`LOCOMOTION_WEIGHTS`, trained by :mod:`torchrl_causal.experts.locomotion`)
and two of the humanoid's (:data:`HUMANOID_LOCOMOTION_BODIES`, trained by
:mod:`torchrl_causal.experts.locomotion_ppo`); the humanoid's may start with a
:class:`CommandFrame`, which turns the observation so the command points one way.

The weights stay in ``torchrl_causal/envs/assets/`` (:data:`ASSETS`), where the regeneration
commands quoted by the archived results write them.
"""

from __future__ import annotations

import math
import pathlib

import torch
from torch import nn

from torchrl_causal.envs.ant import LOCOMOTION_ACTION_DIM, LOCOMOTION_OBSERVATION_DIM
from torchrl_causal.envs.humanoid import COMMAND_FRAME_VECTORS, HUMANOID_SKILL_OBSERVATION_DIM
from torchrl_causal.errors import InvalidStateError, InvalidValueError, MissingFileError

__all__ = [
    "ASSETS",
    "HUMANOID_LOCOMOTION_BODIES",
    "HUMANOID_LOCOMOTION_WEIGHTS",
    "LOCOMOTION_WEIGHTS",
    "CommandFrame",
    "humanoid_body_file",
    "humanoid_skill_network",
    "load_humanoid_locomotion_network",
    "load_locomotion_network",
    "load_skill_network",
    "make_locomotion_network",
    "make_skill_network",
]

#: Where the shipped skill weights are (package data).
ASSETS = pathlib.Path(__file__).resolve().parents[1] / "envs" / "assets"
#: The ant's trained locomotion policy body shipped with the package (a state dict).
LOCOMOTION_WEIGHTS = ASSETS / "ant_locomotion.pt"
#: Where the package ships the trained skill's policy body — the fast gait, (legs2)'s learner at
#: 55.5M env steps, the only body that reaches HumanoidMaze-Large's goal within its horizon.
HUMANOID_LOCOMOTION_WEIGHTS = ASSETS / "humanoid_locomotion.pt"
#: The shipped skill bodies by name, each exported from a committed PPO state
#: (``results/humanoid_locomotion/``). No single body is best on both mazes: the steady 36.5M
#: learner walks HumanoidMaze-Medium at 86.8% (falls rarely) and never reaches Large's goal in
#: 2000 steps; the fast 55.5M learner reaches Large (25.2%) and falls in ~45% of Medium's episodes
#: (55.2%). So each maze's expert config names its body (``results/humanoidmaze_expert.md``).
HUMANOID_LOCOMOTION_BODIES: dict[str, tuple[pathlib.Path, str]] = {
    "fast": (HUMANOID_LOCOMOTION_WEIGHTS, "results/humanoid_locomotion/ppo_legs2_late/resume_state.pt"),
    "steady": (
        HUMANOID_LOCOMOTION_WEIGHTS.with_name("humanoid_locomotion_steady.pt"),
        "results/humanoid_locomotion/ppo_legs2/resume_state.pt",
    ),
}
#: The first slot of the command in the humanoid skill's observation (the last of the turned vectors).
_COMMAND = COMMAND_FRAME_VECTORS[-1]


def make_skill_network(observation_dim: int, action_dim: int, hidden: int = 256) -> nn.Sequential:
    """A skill's policy body: ``observation -> (pre-tanh mean, log-std)``, each ``action_dim`` wide.

    Two hidden ReLU layers of ``hidden`` units (OGBench's 2 x 256 SAC networks).

    Examples:
        >>> make_skill_network(69, 21)(torch.zeros(3, 69)).shape
        torch.Size([3, 42])
    """
    return nn.Sequential(
        nn.Linear(observation_dim, hidden),
        nn.ReLU(),
        nn.Linear(hidden, hidden),
        nn.ReLU(),
        nn.Linear(hidden, 2 * action_dim),
    )


def load_skill_network(path: str | pathlib.Path, network: nn.Module, *, regenerate: str) -> nn.Module:
    """``network`` with the state dict at ``path`` (``torch.load(..., weights_only=True)``), in eval mode.

    Raises:
        FileNotFoundError: naming ``regenerate``, the command that makes the weights.
        RuntimeError: when the file is not a state dict of ``network``'s architecture.
    """
    path = pathlib.Path(path)
    if not path.is_file():
        raise MissingFileError(f"no skill weights at {path}; regenerate them with `{regenerate}`")
    try:
        network.load_state_dict(torch.load(path, map_location="cpu", weights_only=True))
    except Exception as err:  # a truncated file, a foreign pickle or a different architecture
        raise InvalidStateError(f"{path} is not a valid state dict of this skill network: {err}") from err
    return network.eval()


def make_locomotion_network(hidden: int = 256) -> nn.Module:
    """The ant's locomotion policy body: ``observation (29) -> (pre-tanh mean (8), log-std (8))``.

    Examples:
        >>> make_locomotion_network()(torch.zeros(3, LOCOMOTION_OBSERVATION_DIM)).shape
        torch.Size([3, 16])
    """
    return make_skill_network(LOCOMOTION_OBSERVATION_DIM, LOCOMOTION_ACTION_DIM, hidden)


def load_locomotion_network(path: str | pathlib.Path = LOCOMOTION_WEIGHTS) -> nn.Module:
    """The ant's locomotion body with trained weights (``torch.load(..., weights_only=True)``), in eval mode.

    Raises:
        FileNotFoundError: naming the command that regenerates the weights.
        RuntimeError: when the file is not a state dict of :func:`make_locomotion_network`.
    """
    return load_skill_network(
        path,
        make_locomotion_network(),
        regenerate=(
            "python -m torchrl_causal.experts.locomotion --skill ant --output torchrl_causal/envs/assets/ant_locomotion.pt "
            "(about 2.5 CPU-hours)"
        ),
    )


class CommandFrame(torch.nn.Module):
    """Turns a skill observation's ground-plane vectors so the command points at a fixed ``angle``: a yaw-free input.

    The skill's observation is OGBench's: egocentric except three world-frame ground-plane
    vectors, the centre-of-mass velocity (C's x, y), the root's linear velocity (the first two
    of ``qvel``, J) and the command. Open ground, the standing start (uniform yaw) and the
    tremors are all symmetric under a turn of the world about the vertical, so the best
    response to an observation is the same after turning those three vectors together; this
    module picks, per observation, the turn that points the command at ``angle`` (radians from
    +x; the output's command slots are then always ``(cos angle, sin angle)``). Its output is a
    function of the observation alone, so the skill still reads only the expert's variables (no
    yaw, which the observation lacks); what it spares the policy is learning the same steering
    once per world direction. A world-frame body had not learnt that symmetry: the KL stage's
    body at 20.0M, fed this frame, walks straight ahead at 0.27 m/s with ``angle`` 0 and at
    0.68 m/s with ``angle`` -pi/2 (16 envs), which is why a run continuing a world-frame learner
    chooses the angle.

    Its persistent ``command_frame`` buffer holds ``angle`` and marks an exported body that
    starts with this module (:func:`load_humanoid_locomotion_network` rebuilds the network from
    the keys, and the buffer brings the angle back).

    Examples:
        >>> frame = CommandFrame(angle=math.pi / 2)
        >>> observation = torch.randn(3, HUMANOID_SKILL_OBSERVATION_DIM)
        >>> observation[:, -2:] = torch.nn.functional.normalize(observation[:, -2:], dim=-1)
        >>> turned = observation.clone()  # the same situation with the world turned by 90 degrees
        >>> for i in COMMAND_FRAME_VECTORS:
        ...     turned[:, i], turned[:, i + 1] = -observation[:, i + 1], observation[:, i]
        >>> torch.allclose(frame(observation), frame(turned), atol=1e-6), frame(observation)[0, -2:].abs().round().tolist()
        (True, [0.0, 1.0])
    """

    def __init__(self, angle: float = 0.0) -> None:
        super().__init__()
        if not math.isfinite(angle):
            raise InvalidValueError(f"the command frame's angle must be a finite number of radians, got {angle}")
        self.register_buffer("command_frame", torch.tensor(float(angle)))

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        command = observation[..., _COMMAND : _COMMAND + 2]
        angle = self.get_buffer("command_frame")
        target = torch.stack((torch.cos(angle), torch.sin(angle))).to(observation.dtype)
        # cos / sin of (angle - the command's angle): the turn that takes the command onto the target.
        cos = command[..., :1] * target[0] + command[..., 1:] * target[1]
        sin = command[..., :1] * target[1] - command[..., 1:] * target[0]
        out = observation.clone()
        for i in COMMAND_FRAME_VECTORS[:-1]:
            x, y = observation[..., i : i + 1], observation[..., i + 1 : i + 2]
            out[..., i : i + 2] = torch.cat((cos * x - sin * y, sin * x + cos * y), dim=-1)
        out[..., _COMMAND : _COMMAND + 2] = target
        return out


def humanoid_skill_network(hidden: int = 256, *, command_frame: float | None = None) -> torch.nn.Sequential:
    """The humanoid skill's policy body (69 -> 2 x 21), behind a :class:`CommandFrame` at that angle unless ``None``.

    Examples:
        >>> list(humanoid_skill_network(8, command_frame=0.0).state_dict())[:2]
        ['0.command_frame', '1.weight']
    """
    body = make_skill_network(HUMANOID_SKILL_OBSERVATION_DIM, 21, hidden)
    return body if command_frame is None else torch.nn.Sequential(CommandFrame(command_frame), *body)


def _stored_command_frame(path: pathlib.Path) -> float | None:
    """The :class:`CommandFrame` angle the weights at ``path`` start with (``None``: none, or unreadable: the load says why)."""
    try:
        angle = torch.load(path, map_location="cpu", weights_only=True).get("0.command_frame")
    except Exception:  # a missing or corrupt file: load_skill_network's error names it
        return None
    return None if angle is None else float(angle)


def humanoid_body_file(body: str | pathlib.Path = HUMANOID_LOCOMOTION_WEIGHTS) -> pathlib.Path:
    """The weights file of a humanoid skill body: a shipped body's name
    (:data:`HUMANOID_LOCOMOTION_BODIES`) or a path, as it is.

    Examples:
        >>> humanoid_body_file("steady").name, humanoid_body_file("my/skill.pt").as_posix()
        ('humanoid_locomotion_steady.pt', 'my/skill.pt')
    """
    named = HUMANOID_LOCOMOTION_BODIES.get(str(body))
    return pathlib.Path(body) if named is None else named[0]


def load_humanoid_locomotion_network(path: str | pathlib.Path = HUMANOID_LOCOMOTION_WEIGHTS) -> torch.nn.Module:
    """The humanoid skill's 2 x 256 policy body (69 -> 2 x 21) with trained weights, in eval mode
    (behind a :class:`CommandFrame` when the weights were trained with one).

    Args:
        path: a weights file, or the name of a shipped body (:data:`HUMANOID_LOCOMOTION_BODIES`:
            ``"fast"``, ``"steady"``).

    Raises:
        FileNotFoundError: naming the command that makes the weights.

    Examples:
        >>> body = load_humanoid_locomotion_network("steady")
        >>> round(float(body[0].command_frame), 4)  # the angle its command is turned to (-pi/2)
        -1.5708
    """
    _, source = HUMANOID_LOCOMOTION_BODIES.get(str(path), (None, "results/humanoid_locomotion/ppo_legs2/resume_state.pt"))
    path = humanoid_body_file(path)
    return load_skill_network(
        path,
        humanoid_skill_network(command_frame=_stored_command_frame(path)),
        regenerate=(
            f"python -m torchrl_causal.experts.locomotion_ppo --skill humanoid --export-from "
            f"{source} --output {path}  "
            "# in a checkout; the training behind that state: results/humanoid_locomotion/README.md"
        ),
    )
