"""Off-policy imitation (Causal SQIL, Causal IQ-Learn): the paper's Algorithms 2 and 3.

A TorchRL collector steps the imitator's env (the causal window's encoding in
``"observation"``) and fills a policy replay buffer; the demonstrations, encoded by the
same window, fill a static expert buffer with ``"expert"`` = True. Each gradient step
(:class:`~torchrl_causal.trainers.update.ActorCriticUpdate`) draws half its batch from
each buffer (the paper's expert buffer ratio 0.5), updates the twin critics
(cosine-annealed learning rate), the actor and the entropy coefficient with
gradient-norm clipping, then the target critics by Polyak averaging.

The counts are exact: the first ``random_steps`` env steps use uniformly random
actions (a whole number of collector batches, or the config is refused); after ``n``
further env steps ``floor(utd_ratio * n)`` gradient steps have run, interleaved with
collection every ``frames_per_batch`` env steps (by default one step of every batched
env); the cosine schedule of the critic learning rate spans ``algo.schedule_updates``
gradient steps, or exactly the run's number of them when that is null (the paper-faithful
configs), so none runs at learning rate zero. The actor collects in eval mode
(no dropout): the replay buffer holds the policy that is evaluated. With
``algo.loss.absorbing`` the expert and policy transitions get absorbing states
(:func:`~torchrl_causal.objectives.add_absorbing_transitions`).

The policy buffer is a memory-mapped TorchRL storage in the run directory
(``replay/``): a checkpoint records its length and write cursor, never its contents. A run
carried to another machine without it (``python -m torchrl_causal.archive carry=true``: the
run directory less ``replay/``) resumes from its checkpoint and first refills the buffer from
the current policy, ``max(algo.random_steps, algo.batch_size)`` transitions (at most what it held)
that count toward no budget and are recorded as ``refilled_steps``; such a resume is not exact.

Networks, losses, optimisers and the expert buffer live on ``cfg.device``; batches
sampled from the (CPU, memory-mapped) policy buffer are moved there. The envs step on
the CPU and the collector moves observations to the policy and actions back.

``algo.warm_start`` (off in the paper's configs) starts the actor from behaviour cloning
on the expert buffer (:meth:`~OffPolicyILTrainer.clone_expert_actions`), lets it collect
the warm-up steps instead of random actions, and fits the critics to it alone
(:meth:`~OffPolicyILTrainer.fit_critics`) before the first joint update: the soft-Q
update then starts from C-BC's solution instead of spending its first 150-250k env steps
at zero success. ``algo.schedule_updates`` fixes the span of the critic's learning-rate
schedule; without it the schedule spans the run's updates (the paper-faithful configs).
``collector_workers > 1`` steps the envs in that many processes (TorchRL's
:class:`~torchrl.collectors.MultiSyncCollector`), for the MuJoCo mazes whose physics is
the bottleneck. Loss scalars are averaged on the device and read back every
``log_every`` updates, so the update loop never waits for the device.

Resume is exact with one collector worker (the episodes in flight are checkpointed,
:class:`~torchrl_causal.trainers.collection.ResumableCollector`). With several workers
the env processes' episodes are not: a resumed run restarts them, with a seed drawn
from the progress, and so continues differently from an uninterrupted one.
"""

from __future__ import annotations

import logging
import operator
import shutil
from collections.abc import Mapping
from fractions import Fraction
from functools import partial
from typing import Any

import torch
from hydra.utils import instantiate
from omegaconf import DictConfig
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.collectors import MultiSyncCollector
from torchrl.data import LazyMemmapStorage, LazyTensorStorage, TensorDictReplayBuffer

from torchrl_causal.errors import InvalidStateError, InvalidValueError
from torchrl_causal.experiment.builders import TRANSITION_KEYS, instantiate_with_strings, make_imitator_env, make_policy, observation_dim
from torchrl_causal.experiment.device import CPU, matmul_precision
from torchrl_causal.experiment.run_directory import CheckpointError
from torchrl_causal.experiment.timing import timed
from torchrl_causal.objectives import ExpertFlaggedSACLoss, add_absorbing_transitions, eval_mode
from torchrl_causal.trainers.base import Trainer
from torchrl_causal.trainers.collection import ResumableCollector
from torchrl_causal.trainers.update import ActorCriticUpdate
from torchrl_causal.trainers.warm_start import behaviour_clone

__all__ = ["OffPolicyILTrainer"]

_COLLECTED_KEYS = (*TRANSITION_KEYS, ("next", "reward"))

log = logging.getLogger(__name__)


class OffPolicyILTrainer(Trainer):
    """SQIL / IQ-Learn (``cfg.algo.loss``) on causally encoded observations.

    Progress is counted in env steps up to ``cfg.algo.total_steps``.
    """

    unit = "env steps"
    budget_key = "algo.total_steps"

    @classmethod
    def extendable_budget(cls, cfg: DictConfig) -> bool:
        # A cosine schedule over the run's budget makes a longer run another run; one whose
        # span the config fixes (algo.schedule_updates) does not.
        return cfg.algo.critic_scheduler is None or cfg.algo.get("schedule_updates") is not None

    def schedule_span(self) -> int:
        """Updates the critic's learning-rate schedule spans: ``algo.schedule_updates`` when
        the config fixes it, else (the paper-faithful configs) every update of the run."""
        span = self.cfg.algo.get("schedule_updates")
        return int(span) if span is not None else max(1, self.updates_due(self.total))

    @property
    def warm_start(self) -> DictConfig | None:
        """``algo.warm_start`` (``bc_updates``, ``critic_updates``), or ``None`` (the paper's cold start)."""
        return self.cfg.algo.get("warm_start")

    def _required_warm_start(self) -> DictConfig:
        if self.warm_start is None:
            raise InvalidStateError(f"{type(self).__name__}: a warm start needs algo.warm_start (bc_updates, critic_updates)")
        return self.warm_start

    @property
    def policy(self) -> TensorDictModuleBase:
        return self.loss.actor_network

    def _make_loss(self) -> ExpertFlaggedSACLoss:
        algo = self.cfg.algo
        dim, spec = observation_dim(self.env), self.env.action_spec
        # Built on the device before the loss copies them (twin and target critics, alpha).
        # With absorbing states the critic also reads the absorbing flag as one more feature.
        loss = instantiate_with_strings(algo.loss)(
            make_policy(self.cfg, self.env).to(self.device), instantiate(algo.critic)(dim + int(algo.loss.absorbing), spec).to(self.device)
        )
        loss.make_value_estimator(**algo.value_estimator)
        return loss.to(self.device)

    def updates_due(self, progress: int) -> int:
        """Gradient steps owed after ``progress`` env steps: ``floor(utd_ratio * (progress - random_steps))``."""
        utd = Fraction(self.cfg.algo.utd_ratio).limit_denominator(1_000_000)  # exact for 0.25, 0.5, 0.1...
        return max(0, int(utd * (progress - self.cfg.algo.random_steps)))

    def setup(self) -> None:
        algo = self.cfg.algo
        self.workers = self.cfg.collector_workers
        self.env = make_imitator_env(self.cfg, self.window, "train", algo.num_envs // self.workers, self.cfg.seed)
        self.loss = self._make_loss()
        cosine_updates = self.schedule_span()
        self.update = ActorCriticUpdate(
            self.loss,
            actor_optimizer=instantiate(algo.actor_optimizer),
            critic_optimizer=instantiate(algo.critic_optimizer),
            alpha_optimizer=instantiate(algo.alpha_optimizer),
            target_update=instantiate(algo.target_update),
            max_grad_norm=algo.max_grad_norm,
            critic_scheduler=None if algo.critic_scheduler is None else instantiate(algo.critic_scheduler),
            cosine_updates=cosine_updates,
            compile=self.cfg.compile,
            precision=self.precision,
        )
        expert_batch = round(algo.batch_size * algo.expert_ratio)
        if not 1 <= expert_batch < algo.batch_size:
            raise InvalidValueError(
                f"algo.batch_size={algo.batch_size} x algo.expert_ratio={algo.expert_ratio} leaves an empty expert or policy half"
            )
        demos = self._replay_format(self.demonstration_transitions())
        self.expert_buffer = TensorDictReplayBuffer(storage=LazyTensorStorage(demos.numel(), device=self.device), batch_size=expert_batch)
        self.expert_buffer.extend(demos)
        self.policy_buffer = TensorDictReplayBuffer(
            storage=LazyMemmapStorage(algo.buffer_size, scratch_dir=self.run.replay_dir / "storage", existsok=True),
            batch_size=algo.batch_size - expert_batch,
            transform=operator.methodcaller("to", self.device),
        )
        self.log_every = self.cfg.log_every
        #: transitions a run resumed without its replay buffer collects before updating.
        self.refill_target = 0
        self.refilled_steps = 0
        self._reset_scalar_sums()
        # One worker: built now, so that resume can load the episodes in flight into it.
        # Several: built at the first step, from the progress resume has restored.
        self.collector: ResumableCollector | MultiSyncCollector | None = None
        if self.workers == 1:
            self.collector = self._make_collector()
            self.batches = iter(self.collector)

    def _built_collector(self) -> ResumableCollector | MultiSyncCollector:
        if self.collector is None:
            raise InvalidStateError(f"{type(self).__name__}: the collector is not built (or closed already)")
        return self.collector

    def _replay_format(self, transitions: TensorDictBase) -> TensorDictBase:
        return add_absorbing_transitions(transitions) if self.cfg.algo.loss.absorbing else transitions

    def _make_collector(self) -> ResumableCollector | MultiSyncCollector:
        algo = self.cfg.algo
        frames = algo.frames_per_batch
        # A warm-started actor collects the warm-up steps itself: random actions would
        # throw its head start away.
        remaining_random = 0 if self.warm_start else max(0, algo.random_steps - self.progress)
        devices = dict(env_device=CPU, policy_device=self.device, storing_device=self.device)
        with eval_mode(self.policy):  # the collector probes the policy when it is built
            if self.workers == 1:
                return ResumableCollector(
                    self.env,
                    self.policy,
                    frames_per_batch=frames,
                    total_frames=-1,
                    init_random_frames=remaining_random or None,
                    auto_register_policy_transforms=False,
                    **devices,
                )
            # The workers' envs are new processes: their episodes start afresh, seeded by the progress.
            seed = self.cfg.seed * 1_000_003 + self.progress
            make_worker_env = partial(make_imitator_env, self.cfg, self.window, "train", algo.num_envs // self.workers, seed)
            # Every worker counts its own random frames, so each takes its share of them.
            collector = MultiSyncCollector(
                [make_worker_env] * self.workers,
                self.policy,
                frames_per_batch=frames,
                total_frames=-1,
                init_random_frames=remaining_random // self.workers or None,
                cat_results="stack",
                auto_register_policy_transforms=False,
                **devices,
            )
            collector.set_seed(seed)
            return collector

    def _reset_scalar_sums(self) -> None:
        # Sums stay on the device; only the counts, which the host knows, are Python ints.
        self.scalar_sums = torch.zeros(1 + len(ActorCriticUpdate.SCALARS), device=self.device)
        self.batches_since_log = self.updates_since_log = 0

    def _scalar_means(self) -> dict[str, torch.Tensor]:
        """The averages since the last log, still on the device (the logger reads them)."""
        means = {"train/reward_per_step": self.scalar_sums[0] / self.batches_since_log}
        if self.updates_since_log:
            losses = self.scalar_sums[1:] / self.updates_since_log
            means.update({f"train/{name}": value for name, value in zip(ActorCriticUpdate.SCALARS, losses)})
        self._reset_scalar_sums()
        return means

    def clone_expert_actions(self) -> None:
        """Warm start, part 1: ``warm_start.bc_updates`` steps of maximum-likelihood behaviour
        cloning of the actor on the expert buffer (its own Adam, ``algo.actor_optimizer``'s
        settings), before the first env step."""
        updates = self._required_warm_start().bc_updates
        optimizer = instantiate(self.cfg.algo.actor_optimizer)(list(self.loss.actor_network_params.flatten_keys().values()))

        def nll() -> torch.Tensor:
            batch = self.expert_buffer.sample()
            with matmul_precision(self.precision, self.device):
                return self.loss.behaviour_cloning_nll(batch)

        behaviour_clone(nll, optimizer, updates, self.cfg.algo.max_grad_norm)

    def fit_critics(self) -> None:
        """Warm start, part 2: ``warm_start.critic_updates`` critic-only updates on expert and
        policy batches, the warm-started actor held fixed, before the first joint update."""
        updates = self._required_warm_start().critic_updates
        for step in range(1, updates + 1):
            loss = self.update.critic_step(self.sample_batch())
            if step % 1000 == 0 or step == updates:
                log.info("warm start: critic fit %d/%d, critic loss %.3f", step, updates, loss.item())

    def sample_batch(self) -> TensorDictBase:
        """An update's batch: the expert half, then the policy half."""
        with timed("replay sampling"):
            return torch.cat([self.expert_buffer.sample(), self.policy_buffer.sample()], dim=0)

    def _collect(self) -> TensorDictBase:
        """One collector batch of the current policy, stored in the policy buffer."""
        with timed("collection"), eval_mode(self.policy):
            if self.collector is None:
                self.collector = self._make_collector()
                self.batches = iter(self.collector)
            elif self.workers > 1:
                self.collector.update_policy_weights_()
            batch = next(self.batches)
        transitions = batch.reshape(-1).select(*_COLLECTED_KEYS)
        transitions.set("expert", torch.zeros((*transitions.batch_size, 1), dtype=torch.bool, device=transitions.device))
        self.policy_buffer.extend(self._replay_format(transitions.exclude(("next", "reward"))))
        return transitions

    def refill_policy_buffer(self) -> None:
        """Collects with the current policy, without updating or counting progress, until the
        buffer holds :attr:`refill_target` transitions (a run resumed without its buffer)."""
        while len(self.policy_buffer) < self.refill_target:
            self.refilled_steps += self._collect().numel()
        log.info("refilled the replay buffer with %d transitions of the current policy", len(self.policy_buffer))
        self.refill_target = 0

    def train_step(self) -> Mapping[str, torch.Tensor]:
        # A fresh run's warm start: progress and the update count say whether each part ran,
        # so a run resumed from a checkpoint never repeats one.
        if self.warm_start and self.progress == 0 and self.warm_start.bc_updates:
            with timed("warm start (BC)"):
                self.clone_expert_actions()
        if self.refill_target:
            self.refill_policy_buffer()
        transitions = self._collect()
        self.progress += transitions.numel()
        self.env_steps_done += transitions.numel()
        self.scalar_sums[0] += transitions["next", "reward"].mean()
        self.batches_since_log += 1
        owed = self.updates_due(self.progress) - self.update.updates
        if owed > 0 and self.update.updates == 0 and self.warm_start and self.warm_start.critic_updates:
            with timed("warm start (critics)"):
                self.fit_critics()
        with timed("updates"):
            for _ in range(owed):
                self.scalar_sums[1:] += self.update(self.sample_batch())
                self.updates_since_log += 1
        self.updates_done += max(owed, 0)
        due = self.updates_since_log >= self.log_every or self.update.updates == 0 or self.progress >= self.total
        return self._scalar_means() if due else {}

    def close(self) -> None:
        if self.collector is not None:
            self.collector.shutdown()
        self.collector = None

    def finish(self) -> None:
        """Drops the replay buffer of a finished run that cannot be continued."""
        if not self.extendable_budget(self.cfg):
            shutil.rmtree(self.run.replay_dir, ignore_errors=True)

    def training_state(self) -> dict[str, Any]:
        # Zero-copy: the storage already lives in replay/storage; this writes its length,
        # the writer's cursor and the sampler's state beside it.
        self.policy_buffer.dumps(self.run.replay_dir)
        return {
            "loss": self.loss.state_dict(),
            **self.update.state_dict(),
            "policy_buffer_len": len(self.policy_buffer),
            "refilled_steps": self.refilled_steps,
            "collector": self._built_collector().state_dict() if self.workers == 1 else {},
            "scalar_sums": self.scalar_sums,
            "batches_since_log": self.batches_since_log,
            "updates_since_log": self.updates_since_log,
        }

    def load_training_state(self, state: Mapping[str, Any]) -> None:
        self.loss.load_state_dict(state["loss"])
        self.update.load_state_dict(state)
        # Checkpoints written before a carried run could refill its buffer hold no count.
        self.refilled_steps = int(state.get("refilled_steps", 0))
        if state["policy_buffer_len"] and not self.run.replay_dir.exists():
            # Carried to another machine without its buffer (never shipped: gigabytes).
            algo = self.cfg.algo
            self.refill_target = min(int(state["policy_buffer_len"]), max(int(algo.random_steps), int(algo.batch_size)))
            log.warning(
                "%s has no replay buffer (a run carried from another machine?): refilling %d transitions from the current "
                "policy before the next update; this resume is not exact",
                self.run.path,
                self.refill_target,
            )
        elif state["policy_buffer_len"]:
            try:
                self.policy_buffer.loads(self.run.replay_dir)
            except (OSError, ValueError, KeyError) as error:
                raise CheckpointError(f"the replay buffer in {self.run.replay_dir} cannot be read: {error}") from error
            if len(self.policy_buffer) != state["policy_buffer_len"]:
                # The run was killed between saving the buffer and the checkpoint: the
                # buffer holds a few more (valid) transitions than the checkpoint counted.
                log.warning(
                    "the replay buffer in %s holds %d transitions, the checkpoint counted %d; continuing",
                    self.run.replay_dir,
                    len(self.policy_buffer),
                    state["policy_buffer_len"],
                )
        if self.workers == 1:
            self._built_collector().load_state_dict(state["collector"])
        self.scalar_sums = state["scalar_sums"].to(self.device)
        self.batches_since_log = int(state["batches_since_log"])
        self.updates_since_log = int(state["updates_since_log"])
