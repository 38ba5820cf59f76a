"""The SCM layer shared by every confounded env: regimes, strength, horizon, gusts, compass.

Every confounded env is a batched TorchRL :class:`~torchrl.envs.EnvBase` whose keys are the
variables of its :class:`~torchrl_causal.graphs.TimeSliceTemplate`: observed variables are
root keys, variables latent to the imitator live under ``("latent", name)``, the confounder
under ``("scm", name)``. :class:`ConfoundedEnv` owns what every such env shares (argument
validation, seeding, step counting, truncation at ``horizon``, the ``"success"`` flag, partial
resets, partial steps); subclasses implement three hooks (:meth:`~ConfoundedEnv._reset_state`,
:meth:`~ConfoundedEnv._transition`, :meth:`~ConfoundedEnv._observation`).

**Partial steps.** A step whose input carries TorchRL's partial-step mask
(:data:`STEP_MASK_KEY`, ``"_step"``: bool, batch-shaped, what ``EnvBase.rollout(...,
break_when_all_done=True)`` writes and what TorchRL hands through a
:class:`~torchrl.envs.TransformedEnv` to its base env) steps only the rows it sets. A skipped
row is not simulated (a MuJoCo maze does not step its physics nor read its state), its
runtime state (step count, success, gust, the subclass's :attr:`~ConfoundedEnv.runtime_attributes`)
stays as it was, its ``"next"`` entries repeat its input entries (TorchRL's convention for a
skipped step; entries the input lacks are read from the held state) and its reward is 0. The
random numbers a step draws are drawn for the whole batch as in a full step, so the stepped
rows' outcomes are bit-identical to a full step's: :func:`~torchrl_causal.evaluation.evaluate_policy`
uses it to stop simulating episodes that ended.

:class:`GustConfoundedEnv` adds the confounding mechanism of the maze suite: a
piecewise-constant :class:`GustProcess` that pushes the body and enters the reward, and a
:class:`CompassSensor` whose reading mixes the true signal with the gust direction and is
rotated by ``confounding_strength * pi`` in the deployment regime. Both helpers are plain
batched torch functions, so envs that simulate in numpy/MuJoCo can call them on tensors.

**Two kinds of deployment shift** (the ``shift`` argument, :data:`SHIFTS`):

* ``"rotation"`` (the default; the authors' public environment code): the gust process is
  the same in both regimes (5% of 5-step windows, uniform direction), W is
  :class:`CompassSensor`'s near-faithful heading, and deploying rotates the reading by
  ``confounding_strength * pi``. Nothing but the reading moves, so a policy that never reads
  W sees the same episodes in both regimes.
* ``"prior"`` (the paper's text: "when P(U) shifts"): only the gust's distribution moves
  between the regimes (:class:`PriorShift`: a prevailing wind that blows in one direction
  while training and the opposite way when deployed); the dynamics, the reward and W are the
  same functions of U in both, and W is :class:`DivertedCompass`, whose needle the wind turns
  towards its own direction by ``confounding_strength`` of the angle between them (the
  paper's "strength": the compass's diversion by the wind; 0 = a faithful noisy heading).
"""

from __future__ import annotations

import inspect
import math
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from typing import TYPE_CHECKING, Any, ClassVar, Literal

import torch
from hydra.utils import get_class
from tensordict import TensorDict, TensorDictBase
from tensordict.utils import NestedKey
from torchrl.data import Binary, Composite, TensorSpec, Unbounded
from torchrl.envs import EnvBase

from torchrl_causal.errors import InvalidValueError, TorchRLCausalError

if TYPE_CHECKING:
    from torchrl_causal.graphs import TimeSliceTemplate

__all__ = [
    "REGIMES",
    "SHIFTS",
    "STEP_MASK_KEY",
    "CompassSensor",
    "ConfoundedEnv",
    "DivertedCompass",
    "GustConfoundedEnv",
    "GustProcess",
    "GustSensor",
    "PartialStepError",
    "PrevailingGustProcess",
    "PriorShift",
    "batch_rows",
    "rotate",
    "validate_shift",
    "validate_strength",
]

Regime = Literal["train", "deploy"]
REGIMES: tuple[str, ...] = ("train", "deploy")
Shift = Literal["rotation", "prior"]
#: The deployment shifts of a :class:`GustConfoundedEnv`: ``"rotation"`` turns W's reading,
#: ``"prior"`` moves P(U) (see the module docstring).
SHIFTS: tuple[str, ...] = ("rotation", "prior")

#: TorchRL's partial-step entry of a step's input — a batch-shaped bool mask of the envs to
#: step (the others are skipped). ``EnvBase.step`` passes it on to a batch-locked env's
#: ``_step`` when it is neither all True nor all False (it drops an all-True mask and skips
#: the env's ``_step`` altogether for an all-False one).
STEP_MASK_KEY = "_step"


class PartialStepError(TorchRLCausalError, ValueError):
    """A step's partial-step mask (:data:`STEP_MASK_KEY`) that is no bool mask of the env's batch."""


def rotate(vectors: torch.Tensor, angle: float | torch.Tensor) -> torch.Tensor:
    """Rotates 2-D vectors (last dim of size 2) counter-clockwise by ``angle`` radians.

    Examples:
        >>> torch.allclose(rotate(torch.tensor([1.0, 0.0]), math.pi / 2), torch.tensor([0.0, 1.0]), atol=1e-6)
        True
    """
    angle = torch.as_tensor(angle, dtype=vectors.dtype, device=vectors.device)
    cos, sin = torch.cos(angle), torch.sin(angle)
    x, y = vectors.unbind(-1)
    return torch.stack((cos * x - sin * y, sin * x + cos * y), dim=-1)


@dataclass(frozen=True)
class GustProcess:
    """The piecewise-constant gust process of the maze suite (the latent confounder U).

    Every ``period`` steps (counted from the episode start, step 0 included) the gust is
    redrawn: with probability ``probability`` a gust of magnitude ``U[low, high]`` blowing
    in a uniform direction, else calm (a zero vector). Between redraws it stays constant,
    which is what makes U a confounder shared by up to ``period`` consecutive time slices.

    The gust is a force vector of shape ``batch + (2,)``.

    Examples:
        >>> process = GustProcess()
        >>> g = torch.Generator().manual_seed(0)
        >>> gust = process.draw((4096,), generator=g)
        >>> gust.shape
        torch.Size([4096, 2])
        >>> magnitude = gust.norm(dim=-1)
        >>> bool(((magnitude == 0) | ((magnitude >= 2) & (magnitude <= 5))).all())
        True
        >>> step = torch.tensor([[4], [5]])
        >>> held = process.advance(torch.ones(2, 2), step, generator=g)
        >>> held[0].tolist()  # step 4: not a redraw step, the gust persists
        [1.0, 1.0]
    """

    period: int = 5
    probability: float = 0.05
    low: float = 2.0
    high: float = 5.0

    def __post_init__(self) -> None:
        if self.period < 1:
            raise InvalidValueError(f"gust period must be >= 1, got {self.period}")
        if not 0.0 <= self.probability <= 1.0:
            raise InvalidValueError(f"gust probability must lie in [0, 1], got {self.probability}")
        if not 0.0 <= self.low <= self.high:
            raise InvalidValueError(f"gust magnitude range must satisfy 0 <= low <= high, got [{self.low}, {self.high}]")

    def draw(
        self,
        shape: Sequence[int],
        *,
        generator: torch.Generator | None = None,
        device: torch.device | str | None = None,
        dtype: torch.dtype = torch.float32,
    ) -> torch.Tensor:
        """Draws fresh gusts of shape ``shape + (2,)`` (zero where calm)."""
        uniforms = torch.rand((*shape, 3), generator=generator, device=device, dtype=dtype)
        active, magnitude, angle = uniforms.unbind(-1)
        magnitude = torch.where(active < self.probability, self.low + (self.high - self.low) * magnitude, torch.zeros_like(magnitude))
        angle = self.angle(angle)
        return torch.stack((magnitude * torch.cos(angle), magnitude * torch.sin(angle)), dim=-1)

    def angle(self, uniform: torch.Tensor) -> torch.Tensor:
        """The direction (radians) a gust blows towards, from a ``U[0, 1)`` draw: uniform here."""
        return 2 * math.pi * uniform

    def advance(self, gust: torch.Tensor, step_count: torch.Tensor, *, generator: torch.Generator | None = None) -> torch.Tensor:
        """The gust at step ``step_count`` given the gust of the previous step.

        Args:
            gust: the previous gust, shape ``batch + (2,)``.
            step_count: the new step index, shape ``batch + (1,)``; entries at a multiple of
                ``period`` are redrawn, the others keep ``gust``.
        """
        fresh = self.draw(gust.shape[:-1], generator=generator, device=gust.device, dtype=gust.dtype)
        return torch.where(step_count % self.period == 0, fresh, gust)

    @staticmethod
    def direction(gust: torch.Tensor) -> torch.Tensor:
        """Unit vector along each gust (the zero vector where calm)."""
        magnitude = gust.norm(dim=-1, keepdim=True)
        return torch.where(magnitude > 0, gust / magnitude.clamp_min(1e-12), torch.zeros_like(gust))

    @staticmethod
    def exposure(gust: torch.Tensor) -> torch.Tensor:
        """Gust magnitude, shape ``batch + (1,)`` (what the reward penalises)."""
        return gust.norm(dim=-1, keepdim=True)


@dataclass(frozen=True)
class PrevailingGustProcess(GustProcess):
    """A :class:`GustProcess` whose gusts blow around a prevailing direction.

    A gust's direction is uniform on the arc ``prevailing ± spread * pi`` (radians, the
    direction the wind blows towards: 0 is +x, ``pi / 2`` is +y), so ``spread = 1`` is the
    uniform direction of :class:`GustProcess`; the period, probability and magnitudes are
    :class:`GustProcess`'s. It draws the same three uniforms per gust as its base.

    The mean unit direction of its gusts is ``sinc(spread) * (cos prevailing, sin prevailing)``
    with ``sinc(x) = sin(pi x) / (pi x)`` (the mean of ``cos`` over the arc).

    Examples:
        >>> process = PrevailingGustProcess(probability=1.0, prevailing=math.pi / 2, spread=0.25)
        >>> angles = torch.atan2(*process.draw((4096,), generator=torch.Generator().manual_seed(0)).flip(-1).unbind(-1))
        >>> bool(((angles - math.pi / 2).abs() <= math.pi / 4 + 1e-6).all())
        True
    """

    # Not `direction`: that is GustProcess's static method reading a gust's unit direction.
    prevailing: float = 0.0
    spread: float = 1.0

    def __post_init__(self) -> None:
        super().__post_init__()
        if not 0.0 <= self.spread <= 1.0:
            raise InvalidValueError(f"gust spread must lie in [0, 1], got {self.spread}")

    def angle(self, uniform: torch.Tensor) -> torch.Tensor:
        return self.prevailing + 2 * math.pi * self.spread * (uniform - 0.5)

    def mean_direction(self) -> tuple[float, float]:
        """``E[unit direction | a gust blows]`` as ``(x, y)`` (the closed form above)."""
        x = math.pi * self.spread
        length = math.sin(x) / x if x > 0 else 1.0
        return length * math.cos(self.prevailing), length * math.sin(self.prevailing)


@dataclass(frozen=True)
class PriorShift:
    """The P(U)-shift deployment: the gust process of each regime, nothing else.

    Training blows a prevailing wind towards ``pi / 4`` (+x, +y), deployment the opposite
    way (``-3 pi / 4``): the same frequency (a gust in 25% of the 5-step windows, five times
    the rotation regime's 5%, so that the wind diverts W in enough of the demonstrations for
    a learner that reads W to lean on it), the same magnitudes (U[2, 5] N) and the same
    spread (±45° around the prevailing direction). Both directions are perpendicular to the
    Medium mazes' start-to-goal diagonal (+x, -y) and within 12° of perpendicular to
    AntMaze-Large's, so neither regime's wind carries an agent towards its goal more than the
    other's. The period stays 5: the time-slice diagram, whose bidirected edges the period
    sets, is the same under both kinds of shift.

    Examples:
        >>> shift = PriorShift()
        >>> round(math.degrees(shift.process("train").prevailing)), round(math.degrees(shift.process("deploy").prevailing))
        (45, -135)
    """

    train: GustProcess = PrevailingGustProcess(probability=0.25, prevailing=math.pi / 4, spread=0.25)
    deploy: GustProcess = PrevailingGustProcess(probability=0.25, prevailing=-3 * math.pi / 4, spread=0.25)

    def process(self, regime: str) -> GustProcess:
        """The gust process of ``regime``."""
        return self.train if _validate_regime(regime) == "train" else self.deploy


class GustSensor(ABC):
    """What the sensors of W share: ``W = rotate(tanh(mean(signal, gust) + noise), rotation)``.

    ``noise ~ N(0, noise_std**2)`` per component, drawn from ``generator`` for the whole
    batch; subclasses give the noise-free reading :meth:`mean` and the field ``noise_std``.
    One :meth:`read` serves every sensor, so that each draws its noise in the same order
    from the env's generator and the shifts differ only in what the needle points at.

    Examples:
        >>> sensor = DivertedCompass(diversion=0.0, noise_std=0.0)
        >>> north, calm = torch.tensor([[0.0, 1.0]]), torch.zeros(1, 2)
        >>> torch.equal(sensor.read(north, calm, rotation=0.0), torch.tanh(sensor.mean(north, calm)))
        True
    """

    noise_std: float

    @abstractmethod
    def mean(self, signal: torch.Tensor, gust: torch.Tensor) -> torch.Tensor:
        """The reading before noise and ``tanh``, ``signal``'s shape."""

    def read(
        self,
        signal: torch.Tensor,
        gust: torch.Tensor,
        *,
        rotation: float | torch.Tensor,
        generator: torch.Generator | None = None,
    ) -> torch.Tensor:
        """The sensor reading for a batch of ``signal`` (``batch + (2,)``) under ``gust``."""
        noise = torch.randn(signal.shape, generator=generator, device=signal.device, dtype=signal.dtype)
        return rotate(torch.tanh(self.mean(signal, gust) + self.noise_std * noise), rotation)


@dataclass(frozen=True)
class CompassSensor(GustSensor):
    """The imitator's extra sensor W: a collider of the true signal and the gust.

    ``W = rotate(tanh(signal_weight * signal + gust_weight * gust_direction + noise), rotation)``
    with ``noise ~ N(0, noise_std**2)`` per component. ``signal`` is the true unit signal
    (the heading for a compass, the locomotion direction for a vibration sensor). The
    rotation is ``confounding_strength * pi`` in the deployment regime and 0 in training.
    The reading has no causal effect on anything: it is only ever written to the
    observation.

    Examples:
        >>> sensor = CompassSensor(noise_std=0.0)
        >>> east, calm = torch.tensor([[1.0, 0.0]]), torch.zeros(1, 2)
        >>> w = sensor.read(east, calm, rotation=0.0)
        >>> torch.allclose(w, torch.tanh(torch.tensor([[0.9, 0.0]])))
        True
        >>> torch.allclose(sensor.read(east, calm, rotation=math.pi), -w, atol=1e-6)
        True
    """

    signal_weight: float = 0.9
    gust_weight: float = 0.1
    noise_std: float = 0.05

    def mean(self, signal: torch.Tensor, gust: torch.Tensor) -> torch.Tensor:
        """``signal_weight * signal + gust_weight * gust_direction`` (noise-free, pre-``tanh``)."""
        return self.signal_weight * signal + self.gust_weight * GustProcess.direction(gust)


@dataclass(frozen=True)
class DivertedCompass(GustSensor):
    """The sensor W of the P(U)-shift regime: a needle the wind turns towards its direction.

    ``W = rotate(tanh(signal_weight * rotate(signal, diversion * delta) + noise), rotation)``
    where ``delta`` in ``(-pi, pi]`` is the angle from ``signal`` to the gust's direction
    (0 while calm) and ``noise ~ N(0, noise_std**2)`` per component. ``diversion`` is the
    confounding strength: 0 reads the signal whatever the wind (W independent of U given the
    signal), 1 reads the wind's direction while it blows. The reading draws the same noise
    as :class:`CompassSensor`'s; ``rotation`` is 0 in both regimes of the P(U) shift (kept in
    the signature so that both sensors read alike). Like the compass, it has no causal effect
    on anything.

    Examples:
        >>> sensor = DivertedCompass(diversion=0.5, noise_std=0.0)
        >>> north, gust_east = torch.tensor([[0.0, 1.0]]), torch.tensor([[3.0, 0.0]])
        >>> sensor.needle(north, gust_east)  # half-way to the wind
        tensor([[0.7071, 0.7071]])
        >>> torch.equal(sensor.needle(north, torch.zeros(1, 2)), north)  # calm: the heading
        True
    """

    diversion: float = 1.0
    signal_weight: float = 0.9
    noise_std: float = 0.05

    def __post_init__(self) -> None:
        if not 0.0 <= self.diversion <= 1.0:
            raise InvalidValueError(f"compass diversion must lie in [0, 1], got {self.diversion}")

    def needle(self, signal: torch.Tensor, gust: torch.Tensor) -> torch.Tensor:
        """``signal`` turned by ``diversion`` of its angle to the gust's direction (noise-free, pre-``tanh``)."""
        direction = GustProcess.direction(gust)
        x, y = signal.unbind(-1)
        dx, dy = direction.unbind(-1)
        delta = torch.atan2(x * dy - y * dx, x * dx + y * dy)
        # Calm: no turn. (Not atan2's own 0 for a zero vector: with signed zeros, e.g. a
        # westward signal times a zero direction, atan2(-0.0, -0.0) is -pi.)
        calm = gust.norm(dim=-1) == 0
        return rotate(signal, self.diversion * torch.where(calm, torch.zeros_like(delta), delta))

    def mean(self, signal: torch.Tensor, gust: torch.Tensor) -> torch.Tensor:
        """``signal_weight`` times the :meth:`needle` (noise-free, pre-``tanh``)."""
        return self.signal_weight * self.needle(signal, gust)


def _copy_state(value: Any, device: torch.device | None = None) -> Any:
    if isinstance(value, Mapping):
        return {key: _copy_state(item, device) for key, item in value.items()}
    return value.to(device).clone() if device is not None else value.clone()


def _hold_rows(live: torch.Tensor, new: Any, old: Any) -> Any:
    """``new`` where ``live`` (bool, batch-shaped) is set, else ``old``; tensors of shape
    ``batch + event`` or dicts of them (a runtime attribute, see :func:`_copy_state`)."""
    if isinstance(new, Mapping):
        return {key: _hold_rows(live, item, old[key]) for key, item in new.items()}
    return torch.where(live.reshape(*live.shape, *(1,) * (new.dim() - live.dim())), new, old)


def _validate_regime(regime: str) -> str:
    if regime not in REGIMES:
        raise InvalidValueError(f"regime must be one of {REGIMES}, got {regime!r}")
    return regime


def validate_shift(shift: str) -> str:
    """``shift`` when it is one of :data:`SHIFTS`, else an error naming it.

    Examples:
        >>> validate_shift("prior")
        'prior'
        >>> validate_shift("wind")
        Traceback (most recent call last):
        ...
        torchrl_causal.errors.InvalidValueError: shift must be one of ('rotation', 'prior'), got 'wind'
    """
    if shift not in SHIFTS:
        raise InvalidValueError(f"shift must be one of {SHIFTS}, got {shift!r}")
    return shift


def validate_strength(confounding_strength: float) -> float:
    """``confounding_strength`` as a float in ``[0, 1]``: the one rule for the strength, checked
    where it enters (an env's constructor, an evaluation's override; a config's by its schema).

    Raises:
        InvalidValueError: naming the value.

    Examples:
        >>> validate_strength(1)
        1.0
        >>> validate_strength(1.5)
        Traceback (most recent call last):
        ...
        torchrl_causal.errors.InvalidValueError: confounding_strength must lie in [0, 1], got 1.5
    """
    strength = float(confounding_strength)
    if not 0.0 <= strength <= 1.0:
        raise InvalidValueError(f"confounding_strength must lie in [0, 1], got {confounding_strength!r}")
    return strength


class EnvArgumentError(TorchRLCausalError, ValueError):
    """An env constructor's argument out of range, named with its value (raised before the
    env allocates anything)."""


def validate_batch_size(batch_size: object) -> tuple[int, ...]:
    """``batch_size`` as a shape: an int >= 0 or a sequence of them (``()`` for an unbatched env).

    Raises:
        EnvArgumentError: anything else (a float, a negative size, a string), named.

    Examples:
        >>> validate_batch_size(4), validate_batch_size((2, 3)), validate_batch_size(torch.Size([]))
        ((4,), (2, 3), ())
        >>> validate_batch_size(2.0)
        Traceback (most recent call last):
        ...
        torchrl_causal.envs.base.EnvArgumentError: batch_size must be an int >= 0 or a sequence of them, got 2.0
    """
    dims = (batch_size,) if isinstance(batch_size, int) and not isinstance(batch_size, bool) else batch_size
    if isinstance(dims, (str, bytes)) or not isinstance(dims, Sequence):
        raise EnvArgumentError(f"batch_size must be an int >= 0 or a sequence of them, got {batch_size!r}")
    if not all(isinstance(d, int) and not isinstance(d, bool) and d >= 0 for d in dims):
        raise EnvArgumentError(f"batch_size must be an int >= 0 or a sequence of them, got {batch_size!r}")
    return tuple(int(d) for d in dims)


def batch_rows(size: int, rows: Sequence[int] | None) -> list[int]:
    """The flat batch indices a ``render(rows=...)`` draws: ``rows`` checked against a batch
    of ``size`` elements, every row for ``None``.

    Raises:
        InvalidValueError: a row outside ``range(size)``, named.

    Examples:
        >>> batch_rows(3, None), batch_rows(3, [2, 0])
        ([0, 1, 2], [2, 0])
        >>> batch_rows(3, [3])
        Traceback (most recent call last):
        ...
        torchrl_causal.errors.InvalidValueError: render row 3 is outside the batch of 3 elements
    """
    if rows is None:
        return list(range(size))
    for row in rows:
        if isinstance(row, bool) or not isinstance(row, int) or not 0 <= row < size:
            raise InvalidValueError(f"render row {row!r} is outside the batch of {size} elements")
    return list(rows)


def _validate_horizon(horizon: int) -> int:
    if isinstance(horizon, bool) or not isinstance(horizon, int) or horizon < 1:
        raise InvalidValueError(f"horizon must be a positive int, got {horizon!r}")
    return horizon


class ConfoundedEnv(EnvBase):
    """Base class of the SCM-driven envs: a batched TorchRL env over a causal template.

    Subclasses implement:

    * :attr:`causal_template`: the time-slice template that describes the mechanism;
    * optionally :meth:`_terminated` (default: an episode ends for good on success);
    * :meth:`_make_variable_specs`: the specs of ``"action"`` and of the variable keys;
    * :meth:`_reset_state` (draw the initial state where a mask is set),
      :meth:`_transition` (advance one step, return reward and success) and
      ``_observation()`` (the variable entries of the current state).

    The base adds ``"success"`` (bool, ``batch + (1,)``), ``"done"``/``"terminated"``/
    ``"truncated"`` (terminated = success, truncated = ``horizon`` steps reached without
    success), handles partial resets (``"_reset"``) and seeds a private
    :class:`torch.Generator` through :meth:`set_seed`, so that a seed reproduces a rollout.

    The env's runtime state (the generator and the :attr:`runtime_attributes`) is its
    module extra state: ``env.load_state_dict(state)`` with a ``state = env.state_dict()``
    taken mid-episode continues those episodes exactly (a resumed training run).

    Args:
        batch_size: the env's batch shape (any shape, ``()`` included).
        regime: ``"train"`` (demonstration collection) or ``"deploy"`` (evaluation).
        confounding_strength: in ``[0, 1]``; how strongly the deployment regime shifts
            the confounded mechanism (0 = no shift).
        horizon: episodes are truncated after this many steps.
        device: torch device of the env.
        seed: seed of the env's generator (``None`` draws one from torch's global RNG).
    """

    #: attributes holding what changes during episodes; subclasses add theirs.
    runtime_attributes: ClassVar[tuple[str, ...]] = ("_step_count", "_success")

    def __init__(
        self,
        *,
        batch_size: Sequence[int] | torch.Size | int = (),
        regime: Regime = "train",
        confounding_strength: float = 1.0,
        horizon: int = 1000,
        device: torch.device | str | None = None,
        seed: int | None = None,
    ) -> None:
        batch_size = validate_batch_size(batch_size)
        device = torch.device("cpu" if device is None else device)
        super().__init__(device=device, batch_size=torch.Size(batch_size))
        self._regime = _validate_regime(regime)
        self._confounding_strength = validate_strength(confounding_strength)
        self._horizon = _validate_horizon(horizon)
        self.rng = torch.Generator(device=device)
        flag_shape = (*self.batch_size, 1)
        self._step_count = torch.zeros(flag_shape, dtype=torch.int64, device=device)
        self._success = torch.zeros(flag_shape, dtype=torch.bool, device=device)
        self._make_specs()
        self.set_seed(int(torch.randint(0, 2**62, ()).item()) if seed is None else seed)

    # -- configuration -------------------------------------------------------------------

    @property
    def regime(self) -> str:
        """``"train"`` or ``"deploy"``."""
        return self._regime

    @property
    def confounding_strength(self) -> float:
        """Shift strength in ``[0, 1]`` applied by the deployment regime."""
        return self._confounding_strength

    @property
    def horizon(self) -> int:
        """Number of steps after which an episode is truncated."""
        return self._horizon

    @classmethod
    @abstractmethod
    def slice_template(cls) -> TimeSliceTemplate:
        """The time-slice template whose edges this class's mechanism makes true.

        A class-level fact (the mechanism's edges do not depend on the constructor's
        arguments), so a run computes its adjustment window from it without building an env
        (:func:`~torchrl_causal.experiment.builders.make_window`)."""

    @property
    def causal_template(self) -> TimeSliceTemplate:
        """This env's template, :meth:`slice_template` of its class."""
        return self.slice_template()

    def config(self) -> dict[str, object]:
        """JSON-serialisable constructor arguments (recorded with demonstrations)."""
        return {
            "class": f"{type(self).__module__}.{type(self).__qualname__}",
            "batch_size": list(self.batch_size),
            "regime": self.regime,
            "confounding_strength": self.confounding_strength,
            "horizon": self.horizon,
        }

    #: keys of :meth:`config` that report a value derived from the others (not an argument).
    derived_config_keys: ClassVar[tuple[str, ...]] = ()

    @classmethod
    def config_arguments(cls, config: Mapping[str, Any]) -> dict[str, Any]:
        """The constructor's keyword arguments that :meth:`config` recorded (``"class"`` and
        :attr:`derived_config_keys` left out); a subclass that records an argument in another
        form (a dataclass as a dict) turns it back here."""
        return {key: value for key, value in config.items() if key not in ("class", *cls.derived_config_keys)}

    @classmethod
    def from_config(cls, config: Mapping[str, Any], **overrides: Any) -> ConfoundedEnv:
        """The env a :meth:`config` record describes, of the class it names (a subclass of
        ``cls``), with ``overrides`` (e.g. ``batch_size=(1,)``) replacing recorded arguments.

        Raises:
            ValueError: the record names no importable subclass of ``cls``.

        Examples:
            >>> from torchrl_causal.envs import RoverMazeEnv
            >>> env = RoverMazeEnv(maze="u", batch_size=(4,), horizon=300)
            >>> rebuilt = ConfoundedEnv.from_config(env.config(), batch_size=(1,))
            >>> type(rebuilt).__name__, rebuilt.maze, rebuilt.horizon, tuple(rebuilt.batch_size)
            ('RoverMazeEnv', 'u', 300, (1,))
        """
        name = str(config.get("class", ""))
        try:
            target = get_class(name)
        except (ImportError, ValueError, AttributeError):
            target = None
        if not (isinstance(target, type) and issubclass(target, cls)):
            raise InvalidValueError(f"env config class {name!r} is not an importable {cls.__name__}")
        return target(**{**target.config_arguments(config), **overrides})

    def get_extra_state(self) -> dict[str, Any]:
        """The generator's state and a copy of every :attr:`runtime_attributes` entry
        (tensors or dicts of tensors; absent before the first reset).

        Examples:
            >>> from torchrl_causal.envs import RoverMazeEnv
            >>> env = RoverMazeEnv(maze="u", batch_size=(2,), seed=0)
            >>> forward = lambda td: td.set("action", torch.full((2, 2), 0.5))
            >>> td = env.rollout(3, forward)
            >>> saved = env.state_dict()  # mid-episode
            >>> continued = env.rollout(4, forward, auto_reset=False, tensordict=td[..., -1]["next"].clone())
            >>> _ = env.load_state_dict(saved)
            >>> again = env.rollout(4, forward, auto_reset=False, tensordict=td[..., -1]["next"].clone())
            >>> torch.equal(again["next", "P"], continued["next", "P"]), torch.equal(again["W"], continued["W"])
            (True, True)
        """
        state: dict[str, Any] = {"rng": self.rng.get_state()}
        for name in self.runtime_attributes:
            if hasattr(self, name):
                state[name] = _copy_state(getattr(self, name))
        return state

    def set_extra_state(self, state: Mapping[str, Any]) -> None:
        """Inverse of :meth:`get_extra_state`."""
        self.rng.set_state(state["rng"])
        for name in self.runtime_attributes:
            if name in state:
                setattr(self, name, _copy_state(state[name], self.device))

    # -- hooks for subclasses ------------------------------------------------------------

    @abstractmethod
    def _make_variable_specs(self) -> tuple[TensorSpec, Mapping[NestedKey, TensorSpec]]:
        """Returns ``(action_spec, variable_specs)``; specs are sized to ``self.batch_size``."""

    @abstractmethod
    def _reset_state(self, mask: torch.Tensor) -> None:
        """Draws a fresh initial state wherever ``mask`` (bool, ``batch + (1,)``) is set."""

    @abstractmethod
    def _transition(self, action: torch.Tensor, live: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Advances one step under ``action``; returns ``(reward, success)``, each ``batch + (1,)``.

        ``live`` (bool, ``batch + (1,)``), given for a partial step only, names the rows it
        steps. The rows it does not name may be computed or not (their values are
        discarded: :meth:`_step` puts back their :attr:`runtime_attributes`), but an
        implementation must (1) draw its random numbers for the whole batch, as a full step
        does, so the stepped rows get the same ones, and (2) leave any state it keeps
        outside :attr:`runtime_attributes` unchanged in the skipped rows (a MuJoCo maze
        does not step their simulations). A subclass whose ``_transition`` takes no
        ``live`` computes every row of a partial step, which is right when all its state
        is in :attr:`runtime_attributes`.
        """

    @abstractmethod
    def _observation(self) -> dict[str, object]:
        """The variable entries of the current state (nested dicts for nested keys)."""

    def _terminated(self, success: torch.Tensor) -> torch.Tensor:
        """Which episodes end for good this step; reaching success by default."""
        return success.clone()

    def _reset_exogenous(self, mask: torch.Tensor) -> None:
        """Resets exogenous processes (before :meth:`_reset_state`); none by default."""

    def _advance_exogenous(self) -> None:
        """Advances exogenous processes to the new step count; none by default."""

    # -- EnvBase plumbing ----------------------------------------------------------------

    def _make_specs(self) -> None:
        action_spec, variable_specs = self._make_variable_specs()
        observation_spec = Composite(shape=self.batch_size, device=self.device)
        for key, spec in variable_specs.items():
            observation_spec[key] = spec
        observation_spec["success"] = Binary(n=1, shape=(*self.batch_size, 1), device=self.device, dtype=torch.bool)
        self.observation_spec = observation_spec
        self.action_spec = action_spec
        self.reward_spec = Unbounded(shape=(*self.batch_size, 1), device=self.device)
        flag = Binary(n=1, shape=(*self.batch_size, 1), device=self.device, dtype=torch.bool)
        self.done_spec = Composite(done=flag, terminated=flag.clone(), truncated=flag.clone(), shape=self.batch_size, device=self.device)

    def _set_seed(self, seed: int | None) -> None:
        self.rng.manual_seed(int(seed) if seed is not None else int(torch.randint(0, 2**62, ()).item()))

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        mask = None if tensordict is None else tensordict.get("_reset", None)
        if mask is None:
            mask = torch.ones_like(self._success)
        mask = mask.reshape(self._success.shape)
        self._step_count = torch.where(mask, 0, self._step_count)
        self._success = self._success & ~mask
        self._reset_exogenous(mask)
        self._reset_state(mask)
        false = torch.zeros_like(self._success)
        return TensorDict(
            {**self._observation(), "success": self._success.clone(), "done": false, "terminated": false, "truncated": false.clone()},
            batch_size=self.batch_size,
            device=self.device,
        )

    def _live_rows(self, tensordict: TensorDictBase) -> torch.Tensor | None:
        """The partial-step mask of a step's input (:data:`STEP_MASK_KEY`) reshaped to
        ``batch + (1,)``, or ``None`` when it is absent or sets every row."""
        mask = tensordict.get(STEP_MASK_KEY, None)
        if mask is None:
            return None
        if mask.dtype != torch.bool or mask.numel() != self.batch_size.numel():
            raise PartialStepError(
                f"the step's {STEP_MASK_KEY!r} entry must be a bool mask of the env's batch {tuple(self.batch_size)}, "
                f"got dtype {mask.dtype} and shape {tuple(mask.shape)}"
            )
        mask = mask.reshape(self._success.shape).to(self.device)
        return None if bool(mask.all()) else mask

    @classmethod
    @cache
    def _skips_rows(cls) -> bool:
        """Whether this class's :meth:`_transition` takes the partial step's ``live`` rows."""
        return "live" in inspect.signature(cls._transition).parameters

    def _runtime_state(self) -> dict[str, Any]:
        return {name: _copy_state(getattr(self, name)) for name in self.runtime_attributes if hasattr(self, name)}

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        live = self._live_rows(tensordict)
        held = None if live is None else self._runtime_state()
        action = tensordict.get("action")
        reward, success = self._transition(action) if live is None or not self._skips_rows() else self._transition(action, live)
        self._step_count = self._step_count + 1
        self._success = success
        self._advance_exogenous()
        if held is not None and live is not None:  # after every draw of the step, before anything is read from the state
            rows = live.reshape(self.batch_size)
            for name, old in held.items():
                setattr(self, name, _hold_rows(rows, getattr(self, name), old))
        terminated = self._terminated(self._success)
        truncated = (self._step_count >= self.horizon) & ~terminated
        next_tensordict = TensorDict(
            {
                **self._observation(),
                "reward": reward,
                "success": self._success,
                "done": terminated | truncated,
                "terminated": terminated,
                "truncated": truncated,
            },
            batch_size=self.batch_size,
            device=self.device,
        )
        if live is not None:
            self._repeat_skipped_rows(next_tensordict, tensordict, live.reshape(self.batch_size))
        return next_tensordict

    def _repeat_skipped_rows(self, next_tensordict: TensorDictBase, tensordict: TensorDictBase, live: torch.Tensor) -> None:
        """Writes, in place, the ``"next"`` entries of the rows a partial step skipped: their
        input entries (TorchRL's ``EnvBase._skip_tensordict`` convention), the held state's
        where the input lacks one, a zero reward."""
        for key, value in next_tensordict.items(include_nested=True, leaves_only=True):
            previous = torch.zeros_like(value) if key == "reward" else tensordict.get(key, None)
            if previous is not None:
                next_tensordict.set(key, _hold_rows(live, value, previous.to(value.dtype)))


class GustConfoundedEnv(ConfoundedEnv):
    """A :class:`ConfoundedEnv` confounded by the shared gust process and a compass.

    Keeps the gust of the current step in :attr:`gust` (``batch + (2,)``), redrawn by
    :attr:`gust_process` at every multiple of its period, and reads the sensor W with
    :meth:`read_compass`. The gust is exposed under ``("scm", "U")``; subclasses add
    ``scm_observation()`` to their ``_observation()`` and use :meth:`maze_reward` in
    their reward.

    Args:
        shift: ``"rotation"`` (default: the gust process and :attr:`compass` in both regimes,
            the reading rotated when deployed) or ``"prior"`` (:attr:`prior_shift`'s gust
            process of the regime, a :class:`DivertedCompass` diverted by
            ``confounding_strength``, no rotation); see the module docstring.
        **kwargs: :class:`ConfoundedEnv`'s.

    Class attributes:
        gust_process: the :class:`GustProcess` of the rotation shift (period 5, p = 0.05,
            magnitude U[2, 5]); its period is the diagram's under either shift.
        compass: the :class:`CompassSensor` of the rotation shift (0.9 signal + 0.1 gust
            direction + N(0, 0.05²)).
        prior_shift: the :class:`PriorShift` (each regime's gust process) of the prior shift.
        metres_per_unit: metres per world unit of the env's positions, so that the
            distance term of :meth:`maze_reward` reads at the MuJoCo mazes' scale.
    """

    gust_process: GustProcess = GustProcess()
    compass: CompassSensor = CompassSensor()
    prior_shift: PriorShift = PriorShift()
    metres_per_unit: float = 1.0
    runtime_attributes = (*ConfoundedEnv.runtime_attributes, "gust")

    def __init__(self, *, shift: Shift = "rotation", **kwargs: Any) -> None:
        self._shift = validate_shift(shift)
        super().__init__(**kwargs)

    @property
    def shift(self) -> str:
        """``"rotation"`` or ``"prior"``: what deploying changes (see the module docstring)."""
        return self._shift

    @property
    def gusts(self) -> GustProcess:
        """The gust process this env draws U from — :attr:`gust_process` under the rotation
        shift, the regime's process of :attr:`prior_shift` under the prior shift."""
        return self.prior_shift.process(self.regime) if self.shift == "prior" else self.gust_process

    @property
    def sensor(self) -> GustSensor:
        """The sensor W reads through — :attr:`compass` under the rotation shift, a
        :class:`DivertedCompass` diverted by ``confounding_strength`` under the prior shift
        (the same sensor in both regimes)."""
        if self.shift == "prior":
            return DivertedCompass(diversion=self.confounding_strength)
        return self.compass

    @property
    def compass_rotation(self) -> float:
        """Angle by which the sensor reading is rotated, ``strength * pi`` when deployed under
        the rotation shift, else 0 (always 0 under the prior shift)."""
        return self.confounding_strength * math.pi if self.regime == "deploy" and self.shift == "rotation" else 0.0

    def config(self) -> dict[str, object]:
        """:meth:`ConfoundedEnv.config`, plus ``"shift"`` when it is not the default rotation
        (so that records of rotation envs read as they did before the option existed)."""
        config = super().config()
        return config if self.shift == "rotation" else {**config, "shift": self.shift}

    def _make_specs(self) -> None:
        self.gust = torch.zeros((*self.batch_size, 2), device=self.device)
        super()._make_specs()
        self.observation_spec["scm", "U"] = Unbounded(shape=(*self.batch_size, 2), device=self.device)

    def _terminated(self, success: torch.Tensor) -> torch.Tensor:
        """Which episodes end for good this step; reaching success by default."""
        return success.clone()

    def _reset_exogenous(self, mask: torch.Tensor) -> None:
        fresh = self.gusts.draw(self.batch_size, generator=self.rng, device=self.device)
        self.gust = torch.where(mask, fresh, self.gust)

    def _advance_exogenous(self) -> None:
        self.gust = self.gusts.advance(self.gust, self._step_count, generator=self.rng)

    def read_compass(self, signal: torch.Tensor) -> torch.Tensor:
        """W for the true ``signal`` under the current gust, regime and shift."""
        return self.sensor.read(signal, self.gust, rotation=self.compass_rotation, generator=self.rng)

    def maze_reward(self, success: torch.Tensor, distance: torch.Tensor) -> torch.Tensor:
        """The maze suite's per-step reward ``1{success} - |U_t| (1 + d_t / 25)``, ``batch + (1,)``.

        ``U_t`` is the gust blowing during the step and ``d_t`` the distance to the goal
        (world units, converted to metres by :attr:`metres_per_unit`) at the step's end.
        Summed over an episode this is the paper's raw E[Y]: about -370 for a 1000-step
        failure (the gust blows 5% of the time at 3.5 on average), near -100 for an
        expert that succeeds in ~300 steps. The same function of U under either shift: the
        prior shift's gusts blow 25% of the time, so its returns are about 5 times lower.

        Examples:
            >>> from torchrl_causal.envs import RoverMazeEnv  # 4 m per cell
            >>> env = RoverMazeEnv(batch_size=(2,), seed=0)
            >>> env.gust = torch.tensor([[3.0, 4.0], [0.0, 0.0]])
            >>> env.maze_reward(torch.tensor([[False], [True]]), torch.tensor([[6.25], [0.0]])).tolist()
            [[-10.0], [1.0]]
        """
        metres = distance * self.metres_per_unit
        return success.to(self.gust.dtype) - GustProcess.exposure(self.gust) * (1.0 + metres / 25.0)

    def scm_observation(self) -> dict[str, dict[str, torch.Tensor]]:
        """The ``("scm", "U")`` entry (diagnostics only: no agent may read it)."""
        return {"scm": {"U": self.gust.clone()}}
