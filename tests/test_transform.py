"""CausalWindowTransform: exact encodings, partial resets, offline = online, specs, state, errors.

The env below makes every value a closed-form function of (episode step t, env index i),
so the expected encoding of Algorithm 2 (concatenate each admissible variable at lags
0..k, the previous actions at lags 1..k, zero before the episode's first step) can be
written independently of the transform's buffers.
"""

from __future__ import annotations

import io
from dataclasses import replace

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from tensordict import TensorDict, TensorDictBase
from torchrl.data import (
    Bounded,
    Composite,
    LazyTensorStorage,
    RandomSampler,
    ReplayBuffer,
    SamplerWithoutReplacement,
    SliceSampler,
    Unbounded,
)
from torchrl.envs import Compose, EnvBase, InitTracker, SerialEnv, TransformedEnv
from torchrl.envs.utils import check_env_specs

from torchrl_causal.graphs import AdjustmentWindow, TimeSliceTemplate
from torchrl_causal.transforms import CausalWindowTransform

# --------------------------------------------------------------------------- tiny env


def p_value(t: torch.Tensor, i: torch.Tensor) -> torch.Tensor:
    """Observed P_t (2 dims, >= 1 so its spec excludes the zero padding)."""
    return torch.stack([t + 1.0, i + 1.0], -1)


def v_value(t: torch.Tensor, i: torch.Tensor) -> torch.Tensor:
    """Observed V_t (1 dim)."""
    return (-(t + 1.0) * (i + 1.0) - 0.5).unsqueeze(-1)


def w_value(t: torch.Tensor, i: torch.Tensor) -> torch.Tensor:
    """The collider W_t (1 dim), excluded by causal windows."""
    return (1000.0 + t + 10.0 * i).unsqueeze(-1)


def action_value(t: torch.Tensor, i: torch.Tensor) -> torch.Tensor:
    """What :func:`counting_policy` plays at step t in env i."""
    return (10.0 * (t + 1.0) + i).unsqueeze(-1)


def counting_policy(td: TensorDictBase) -> TensorDictBase:
    """Reads the raw admissible key P (the transform keeps it) and plays action_value."""
    p = td["P"]
    return td.set("action", action_value(p[..., 0] - 1, p[..., 1] - 1))


class CountingEnv(EnvBase):
    """Env i of the batch runs episodes of ``lengths[i]`` steps; values encode (t, i)."""

    def __init__(self, lengths=(2, 3, 4, 5), drop: str | None = None) -> None:
        lengths = torch.as_tensor(lengths)
        super().__init__(batch_size=lengths.shape)
        self.lengths = lengths
        self.index = torch.arange(lengths.numel()).reshape(lengths.shape).float()
        self.t = torch.zeros(lengths.shape)
        batch = self.batch_size
        specs = {
            "P": Bounded(1.0, 1000.0, shape=(*batch, 2)),
            "V": Unbounded(shape=(*batch, 1)),
            "W": Bounded(1000.0, 2000.0, shape=(*batch, 1)),
            "latent": Composite(O=Unbounded(shape=(*batch, 1)), shape=batch),
            "scm": Composite(U=Unbounded(shape=(*batch, 1)), shape=batch),  # the confounder
        }
        specs.pop(drop, None)
        self.observation_spec = Composite(specs, shape=batch)
        self.action_spec = Bounded(-1000.0, 1000.0, shape=(*batch, 1))
        self.reward_spec = Unbounded(shape=(*batch, 1))

    def _observe(self) -> TensorDict:
        t, i = self.t, self.index
        values = {
            "P": p_value(t, i),
            "V": v_value(t, i),
            "W": w_value(t, i),
            ("latent", "O"): -t.unsqueeze(-1),
            ("scm", "U"): 7 * t.unsqueeze(-1),
        }
        keys = set(self.observation_spec.keys(True, True))
        return TensorDict({key: v for key, v in values.items() if key in keys}, batch_size=self.batch_size)

    def _reset(self, tensordict: TensorDictBase | None) -> TensorDictBase:
        reset = None if tensordict is None else tensordict.get("_reset", None)
        if reset is None:
            self.t.zero_()
        else:
            self.t[reset.reshape(self.batch_size)] = 0
        out = self._observe()
        out["done"] = torch.zeros((*self.batch_size, 1), dtype=torch.bool)
        out["terminated"] = out["done"].clone()
        return out

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        self.t += 1
        out = self._observe()
        out["done"] = (self.t >= self.lengths).unsqueeze(-1)
        out["terminated"] = out["done"].clone()
        out["reward"] = tensordict["action"].clone()
        return out

    def _set_seed(self, seed: int | None) -> None:
        """Deterministic env."""

    @property
    def causal_template(self) -> TimeSliceTemplate:
        """P and V drive P, the reward's parent; the latent O drives X and the collider W."""
        return TimeSliceTemplate(
            variables=("P", "V", "O", "W", "X"),
            action="X",
            observed=("P", "V", "W", "X"),
            directed=(("P", "P", 1), ("V", "P", 1), ("X", "P", 1), ("V", "V", 1), ("O", "X", 0), ("O", "W", 0)),
            reward_parents=("P",),
        )


# --------------------------------------------------------------------------- windows and reference

K = 2
CAUSAL = AdjustmentWindow(
    k=K, action="X", lags={"P": (0, 1, 2), "V": (0, 2), "X": (1, 2)}, excluded=frozenset({"W"}), observed=("P", "V", "W", "X")
)
NONCAUSAL = AdjustmentWindow(k=1, action="X", lags={"P": (0,), "V": (0,), "W": (0,), "X": (1,)}, observed=("P", "V", "W", "X"))
MATCHED = AdjustmentWindow(
    k=K, action="X", lags={"P": (0, 1, 2), "V": (0, 1, 2), "W": (0, 1, 2), "X": (1, 2)}, observed=("P", "V", "W", "X")
)
VALUE = {"P": p_value, "V": v_value, "W": w_value, "X": action_value}


def expected_encoding(window: AdjustmentWindow, t: int, i: int) -> torch.Tensor:
    """Encode(s, t) of env i, `t` steps into its episode, from the closed forms above."""
    blocks = []
    for var, lags in window.lags.items():
        for lag in lags:
            value = VALUE[var](torch.tensor(float(t - lag)), torch.tensor(float(i)))
            blocks.append(value if t - lag >= 0 else torch.zeros_like(value))
    return torch.cat(blocks)


def episode_steps(lengths: list[int], steps: int) -> list[list[int]]:
    """Per env, the within-episode step of the root observation at rollout steps 0..steps-1."""
    return [[s % n for s in range(steps)] for n in lengths]


# --------------------------------------------------------------------------- layout


def test_feature_layout_follows_window_order_then_increasing_lag():
    transform = CausalWindowTransform(CAUSAL)
    layout = transform.feature_layout({"P": (2,), "V": (1,), "X": (1,)})
    assert [(f.variable, f.lag) for f in layout] == [("P", 0), ("P", 1), ("P", 2), ("V", 0), ("V", 2), ("X", 1), ("X", 2)]
    starts = [f.columns.start for f in layout]
    assert starts == [0, 2, 4, 6, 7, 8, 9] and layout[-1].columns.stop == 10


# --------------------------------------------------------------------------- exact online values


def test_single_env_exact_tensors_with_zero_padding():
    env = TransformedEnv(CountingEnv(lengths=[5]), CausalWindowTransform(CAUSAL))
    rollout = env.rollout(3, counting_policy)
    # columns: P_t (2), P_{t-1} (2), P_{t-2} (2), V_t, V_{t-2}, X_{t-1}, X_{t-2}; env index 0
    expected = torch.tensor(
        [
            [1, 1, 0, 0, 0, 0, -1.5, 0, 0, 0],
            [2, 1, 1, 1, 0, 0, -2.5, 0, 10, 0],
            [3, 1, 2, 1, 1, 1, -3.5, -1.5, 20, 10],
        ]
    )
    torch.testing.assert_close(rollout["observation"][0], expected, rtol=0, atol=0)
    torch.testing.assert_close(
        rollout["next", "observation"][0, -1],
        torch.tensor([4.0, 1, 3, 1, 2, 1, -4.5, -2.5, 30, 20]),
        rtol=0,
        atol=0,
    )
    # exactly what the imitator's collector stores: no W, no latent, no confounder
    remaining = {"observation", "P", "V", "action", "done", "terminated"}
    assert set(rollout.keys()) == remaining | {"next"}
    assert set(rollout["next"].keys()) == remaining - {"action"} | {"reward"}
    assert set(env.observation_spec.keys()) == {"observation", "P", "V"}


def test_an_imitator_collector_on_rover_maze_stores_no_confounder():
    from torchrl.collectors import Collector

    from torchrl_causal.envs import RoverMazeEnv

    base = RoverMazeEnv(maze="u", batch_size=[4], seed=0)
    assert ("scm", "U") in base.observation_spec.keys(True, True)
    env = TransformedEnv(base, CausalWindowTransform.from_env(base, k=2))
    collector = Collector(env, policy=None, frames_per_batch=4 * 8, total_frames=4 * 8)
    batch = next(iter(collector))
    collector.shutdown()
    step = {"observation", "P", "L", "success", "done", "terminated", "truncated"}
    assert set(batch.keys()) == step | {"action", "collector", "next"}
    assert set(batch["next"].keys()) == step | {"reward"}


def test_observed_variables_outside_the_window_are_hidden_too():
    window = AdjustmentWindow(k=1, action="X", lags={"P": (0,), "X": (1,)}, observed=("P", "V", "W", "X"))
    env = TransformedEnv(CountingEnv([3]), CausalWindowTransform(window))
    assert set(env.observation_spec.keys()) == {"observation", "P"}
    assert not {"V", "W", "latent", "scm"} & set(env.rollout(2, counting_policy).keys())


@pytest.mark.parametrize("window", [CAUSAL, NONCAUSAL, MATCHED], ids=["causal", "noncausal", "matched"])
def test_batch_of_4_with_partial_resets_matches_closed_form(window):
    lengths = [2, 3, 4, 5]
    env = TransformedEnv(CountingEnv(lengths), CausalWindowTransform(window))
    steps = 9
    rollout = env.rollout(steps, counting_policy, break_when_any_done=False)
    for i, env_steps in enumerate(episode_steps(lengths, steps)):
        for s, t in enumerate(env_steps):
            torch.testing.assert_close(rollout["observation"][i, s], expected_encoding(window, t, i), rtol=0, atol=0)
            torch.testing.assert_close(rollout["next", "observation"][i, s], expected_encoding(window, t + 1, i), rtol=0, atol=0)
    assert ("W" in rollout.keys()) == ("W" in window.lags)


def test_explicit_partial_reset_clears_only_the_masked_env():
    env = TransformedEnv(CountingEnv([50, 50, 50, 50]), CausalWindowTransform(CAUSAL))
    td = env.reset()
    for _ in range(3):
        td = env.step(counting_policy(td))["next"]
    reset = torch.tensor([False, True, False, True]).unsqueeze(-1)
    td = env.reset(td.set("_reset", reset))
    for _ in range(2):
        td = env.step(counting_policy(td))["next"]
    for i, t in enumerate([5, 2, 5, 2]):
        torch.testing.assert_close(td["observation"][i], expected_encoding(CAUSAL, t, i), rtol=0, atol=0)


def test_any_batch_shape():
    lengths = torch.tensor([[2, 3], [4, 5]])
    env = TransformedEnv(CountingEnv(lengths), CausalWindowTransform(CAUSAL))
    rollout = env.rollout(6, counting_policy, break_when_any_done=False)
    assert rollout["observation"].shape == (2, 2, 6, 10)
    for i, n in enumerate(lengths.flatten().tolist()):
        for s in range(6):
            torch.testing.assert_close(rollout["observation"].flatten(0, 1)[i, s], expected_encoding(CAUSAL, s % n, i), rtol=0, atol=0)


# --------------------------------------------------------------------------- offline = online


def random_window(data) -> AdjustmentWindow:
    k = data.draw(st.integers(0, 4), label="k")
    lag_sets = {
        "P": data.draw(st.sets(st.integers(0, k), min_size=1), label="P lags"),
        "V": data.draw(st.sets(st.integers(0, k)), label="V lags"),
        "X": data.draw(st.sets(st.integers(1, k)) if k else st.just(set()), label="X lags"),
    }
    return AdjustmentWindow(k=k, action="X", lags={var: tuple(sorted(lags)) for var, lags in lag_sets.items()}, excluded=frozenset({"W"}))


@settings(max_examples=25, deadline=None)
@given(data=st.data())
def test_offline_encoding_equals_online_on_random_episodes(data):
    window = random_window(data)
    lengths = data.draw(st.lists(st.integers(1, 7), min_size=1, max_size=4), label="episode lengths")
    steps = data.draw(st.integers(1, 16), label="rollout steps")
    seed = data.draw(st.integers(0, 2**16), label="seed")
    generator = torch.Generator().manual_seed(seed)

    def random_policy(td):
        return td.set("action", torch.randn(td["P"].shape[:-1] + (1,), generator=generator))

    env = TransformedEnv(CountingEnv(lengths), Compose(InitTracker(), CausalWindowTransform(window)))
    rollout = env.rollout(steps, random_policy, break_when_any_done=False)
    online = rollout.select("observation", ("next", "observation"))

    # The dataset contract: episodes concatenated into one flat, time-ordered [N] batch.
    flat = rollout.exclude("observation", ("next", "observation")).reshape(-1)
    offline = CausalWindowTransform(window, chunk_size=data.draw(st.integers(1, 9), label="chunk")).encode_trajectories(flat)
    torch.testing.assert_close(offline["observation"], online["observation"].reshape(flat.numel(), -1), rtol=0, atol=0)
    torch.testing.assert_close(offline["next", "observation"], online["next", "observation"].reshape(flat.numel(), -1), rtol=0, atol=0)
    # Batched [B, T] rollouts without is_init: episodes delimited by ("next", "done") and row starts.
    batched = CausalWindowTransform(window).encode_trajectories(rollout.exclude("is_init", "observation"))
    torch.testing.assert_close(batched["observation"], online["observation"], rtol=0, atol=0)


def test_encode_trajectories_hides_keys_and_calling_the_transform_on_a_batch_is_refused():
    env = TransformedEnv(CountingEnv([3, 4]), InitTracker())
    rollout = env.rollout(7, counting_policy, break_when_any_done=False).reshape(-1)
    transform = CausalWindowTransform(CAUSAL)
    encoded = transform.encode_trajectories(rollout)
    for level in (encoded, encoded["next"]):
        assert not {"W", "latent", "scm"} & set(level.keys())
    for row, t in enumerate([s % 3 for s in range(7)] + [s % 4 for s in range(7)]):
        torch.testing.assert_close(encoded["observation"][row], expected_encoding(CAUSAL, t, row // 7), rtol=0, atol=0)
    with pytest.raises(RuntimeError, match="encode_trajectories.*make_rb_transform_and_sample_unit"):
        transform(rollout)


# --------------------------------------------------------------------------- specs and batched envs


FROM_ENV_MODES = {
    "causal": ({"causal": True}, {"P": (0, 1, 2), "V": (0, 1, 2), "X": (1, 2)}),
    "noncausal": ({"causal": False}, {"P": (0,), "V": (0,), "W": (0,), "X": (1,)}),
    "matched": ({"causal": False, "window_matched": True}, {"P": (0, 1, 2), "V": (0, 1, 2), "W": (0, 1, 2), "X": (1, 2)}),
}


@pytest.mark.parametrize("mode", list(FROM_ENV_MODES))
def test_from_env_windows_pass_check_env_specs_with_exact_bounds(mode):
    kwargs, lags = FROM_ENV_MODES[mode]
    base = CountingEnv([2, 3, 4, 5])
    transform = CausalWindowTransform.from_env(base, K, **kwargs)
    assert dict(transform.window.lags) == lags and list(transform.window.lags) == list(lags)
    env = TransformedEnv(base, transform)
    check_env_specs(env)
    spec = env.observation_spec["observation"]
    layout = transform.feature_layout()
    assert spec.shape == (4, sum(f.columns.stop - f.columns.start for f in layout)) and spec.dtype == torch.float32
    for feature in layout:
        low, high = spec.space.low[:, feature.columns], spec.space.high[:, feature.columns]
        if feature.variable == "P":  # P's spec is [1, 1000]; zero padding widens the lagged copies
            assert (low == (0.0 if feature.lag else 1.0)).all() and (high == 1000.0).all()
        elif feature.variable == "V":  # unbounded
            assert torch.isinf(low).all() and torch.isinf(high).all()
        elif feature.variable == "W":
            assert (low == (0.0 if feature.lag else 1000.0)).all() and (high == 2000.0).all()
        else:  # the action: [-1000, 1000] contains 0 already
            assert (low == -1000.0).all() and (high == 1000.0).all()
    assert ("W" in env.observation_spec.keys()) is ("W" in lags)
    assert "latent" not in env.observation_spec.keys()


def test_from_env_refuses_window_matched_causal_and_envs_without_template():
    with pytest.raises(ValueError, match="window_matched"):
        CausalWindowTransform.from_env(CountingEnv([3]), 2, causal=True, window_matched=True)

    class NoTemplateEnv(CountingEnv):
        causal_template = None

    with pytest.raises(AttributeError, match="NoTemplateEnv exposes no causal_template"):
        CausalWindowTransform.from_env(NoTemplateEnv([3]), 2)


def test_serial_env_of_transformed_envs_and_transformed_serial_env():
    def make():
        return TransformedEnv(CountingEnv(3), CausalWindowTransform(CAUSAL))  # unbatched workers

    inner = SerialEnv(2, make)
    outer = TransformedEnv(SerialEnv(2, lambda: CountingEnv(3)), CausalWindowTransform(CAUSAL))
    for env in (inner, outer):
        check_env_specs(env)
        rollout = env.rollout(5, counting_policy, break_when_any_done=False)
        for i in range(2):
            for s in range(5):
                # every worker is env index 0 of its own CountingEnv
                torch.testing.assert_close(rollout["observation"][i, s], expected_encoding(CAUSAL, s % 3, 0), rtol=0, atol=0)


def make_transformed_counting_env() -> TransformedEnv:
    return TransformedEnv(CountingEnv(3), CausalWindowTransform(CAUSAL))


def make_counting_env() -> CountingEnv:
    return CountingEnv(3)


class CollidingEnv(CountingEnv):
    """CountingEnv whose W also drives P: a different template, the same specs."""

    @property
    def causal_template(self) -> TimeSliceTemplate:
        template = super().causal_template
        return replace(template, directed=(*template.directed, ("W", "P", 1)))


def make_colliding_env() -> CollidingEnv:
    return CollidingEnv(3)


@pytest.mark.slow
def test_parallel_env_workers_encode():
    from torchrl.envs import ParallelEnv

    env = ParallelEnv(1, make_transformed_counting_env)
    try:
        rollout = env.rollout(5, counting_policy, break_when_any_done=False)
        for s in range(5):
            torch.testing.assert_close(rollout["observation"][0, s], expected_encoding(CAUSAL, s % 3, 0), rtol=0, atol=0)
        # a running ParallelEnv: the template comes from the workers
        assert CausalWindowTransform.from_env(env, K).window == CausalWindowTransform.from_env(CountingEnv(3), K).window
    finally:
        env.close()
    assert CausalWindowTransform.from_env(env, K).window.lags == {"P": (0, 1, 2), "V": (0, 1, 2), "X": (1, 2)}
    assert env.is_closed


def test_from_env_reads_the_template_of_batched_envs_started_or_not(monkeypatch):
    from torchrl.envs import ParallelEnv

    expected = CausalWindowTransform.from_env(CountingEnv(3), K).window
    env = SerialEnv(3, make_counting_env)
    built = []
    monkeypatch.setattr(CountingEnv, "close", lambda self, **kwargs: built.append(self))
    for stage in ("not started", "running", "closed"):
        if stage == "running":
            env.reset()
        elif stage == "closed":
            env.close()
        built.clear()
        assert CausalWindowTransform.from_env(env, K).window == expected, stage
        assert CausalWindowTransform.from_env(TransformedEnv(env, InitTracker()), K).window == expected, stage
        # a batched env that is not running is not started: one env per distinct constructor (one
        # per call here), closed after
        assert len(built) == (0 if stage == "running" else 2) and env.is_closed == (stage != "running")
    parallel = ParallelEnv(2, make_counting_env)  # not started: no worker process is spawned
    assert CausalWindowTransform.from_env(parallel, K).window == expected and parallel.is_closed

    mixed = SerialEnv(2, [make_counting_env, make_colliding_env])
    for stage in ("not started", "running"):
        with pytest.raises(ValueError, match="sub-env 1 of SerialEnv has another causal template than sub-env 0"):
            CausalWindowTransform.from_env(mixed, K)
        mixed.reset()
    mixed.close()


def test_collector_batches_carry_the_encoding():
    from torchrl.collectors import Collector

    env = TransformedEnv(CountingEnv([2, 3, 4, 5]), CausalWindowTransform(CAUSAL))
    collector = Collector(env, counting_policy, frames_per_batch=4 * 6, total_frames=4 * 12)
    for n_batch, batch in enumerate(collector):
        for i, length in enumerate([2, 3, 4, 5]):
            for s in range(6):
                t = (6 * n_batch + s) % length
                torch.testing.assert_close(batch["observation"][i, s], expected_encoding(CAUSAL, t, i), rtol=0, atol=0)
    collector.shutdown()
    assert n_batch == 1


# --------------------------------------------------------------------------- state


def test_state_dict_round_trip_reloads_the_same_encoding():
    env = TransformedEnv(CountingEnv([3, 4]), CausalWindowTransform(CAUSAL))
    env.rollout(2, counting_policy)
    buffer = io.BytesIO()
    torch.save(env.transform.state_dict(), buffer)
    buffer.seek(0)
    state = torch.load(buffer, weights_only=True)

    reloaded = CausalWindowTransform.from_state_dict(state)
    assert reloaded.window == CAUSAL and list(reloaded.window.lags) == list(CAUSAL.lags)
    assert reloaded.feature_layout() == env.transform.feature_layout()  # shapes travel with the state
    data = TransformedEnv(CountingEnv([3, 4]), InitTracker()).rollout(6, counting_policy, break_when_any_done=False)
    torch.testing.assert_close(
        reloaded.encode_trajectories(data)["observation"],
        CausalWindowTransform(CAUSAL).encode_trajectories(data)["observation"],
        rtol=0,
        atol=0,
    )
    CausalWindowTransform(CAUSAL).load_state_dict(state)  # same window: accepted
    with pytest.raises(ValueError, match="different adjustment window"):
        CausalWindowTransform(MATCHED).load_state_dict(state)
    reordered = AdjustmentWindow(k=K, action="X", lags={"V": (0, 2), "P": (0, 1, 2), "X": (1, 2)}, excluded=CAUSAL.excluded)
    with pytest.raises(ValueError, match="different adjustment window"):
        CausalWindowTransform(reordered).load_state_dict(state)
    with pytest.raises(ValueError, match="out_key"):
        CausalWindowTransform(CAUSAL, out_key="z").load_state_dict(state)


# --------------------------------------------------------------------------- bad input


def test_missing_key_is_named():
    named_v = r"window variable \W+V\W+ \(key"
    with pytest.raises(KeyError, match=named_v):
        TransformedEnv(CountingEnv([3], drop="V"), CausalWindowTransform(CAUSAL)).observation_spec
    data = TransformedEnv(CountingEnv([3]), InitTracker()).rollout(3, counting_policy)
    with pytest.raises(KeyError, match=named_v):
        CausalWindowTransform(CAUSAL).encode_trajectories(data.exclude("V"))
    with pytest.raises(KeyError, match="is_init"):
        CausalWindowTransform(CAUSAL).encode_trajectories(data.exclude("is_init", ("next", "done")))


def test_shape_mismatch_is_named():
    env = TransformedEnv(CountingEnv([3]), CausalWindowTransform(CAUSAL))
    data = env.rollout(3, counting_policy)
    wrong = data.exclude("observation", ("next", "observation"))
    wrong["V"] = torch.zeros(1, 3, 3)
    with pytest.raises(ValueError, match=r"shape mismatch for key 'V': this transform encodes events of shape \(1,\)"):
        env.transform.encode_trajectories(wrong)
    td = env.reset().set("action", torch.zeros(1, 2))
    with pytest.raises(ValueError, match=r"shape mismatch for key 'action': expected \(1, 1\), got \(1, 2\)"):
        env.step(td)


def test_negative_window_size_is_refused():
    with pytest.raises(ValueError, match="k must be an int >= 0"):
        AdjustmentWindow(k=-1, action="X", lags={})
    with pytest.raises(ValueError, match="k must be an int >= 0, got -1"):
        CausalWindowTransform.from_env(CountingEnv([3]), -1)


def test_nan_in_an_admissible_key_is_refused_and_the_check_can_be_disabled():
    data = TransformedEnv(CountingEnv([4]), InitTracker()).rollout(4, counting_policy)
    data["V"][0, 2] = float("nan")
    with pytest.raises(ValueError, match="NaN in admissible key 'V'"):
        CausalWindowTransform(CAUSAL).encode_trajectories(data)
    encoded = CausalWindowTransform(CAUSAL, check_nan=False).encode_trajectories(data)
    assert torch.isnan(encoded["observation"][0, 2]).any()
    data["V"][0, 2] = 0.0
    data["W"][0, 2] = float("nan")  # W is not admissible: not the policy's concern
    CausalWindowTransform(CAUSAL).encode_trajectories(data)

    class NanEnv(CountingEnv):
        def _step(self, tensordict):
            return super()._step(tensordict).set("P", torch.full((*self.batch_size, 2), float("nan")))

    with pytest.raises(ValueError, match="NaN in admissible key 'P'"):
        TransformedEnv(NanEnv([4]), CausalWindowTransform(CAUSAL)).rollout(3, counting_policy)


def test_action_key_missing_from_env_is_named():
    with pytest.raises(KeyError, match=r"window variable \W+X\W+ \(key \W+torque"):
        TransformedEnv(CountingEnv([3]), CausalWindowTransform(CAUSAL, action_key="torque")).observation_spec


def test_discrete_specs_give_their_integer_ranges():
    from torchrl.data import Binary, Categorical, MultiCategorical, OneHot

    from torchrl_causal.transforms._layout import spec_bounds

    cases = [  # batch of 2 in front of each event shape
        (Categorical(5, shape=(2,)), [0], [4]),
        (OneHot(3, shape=(2, 3)), [0] * 3, [1] * 3),
        (Binary(n=2, shape=(2, 2)), [0] * 2, [1] * 2),
        (MultiCategorical([2, 4], shape=(2, 2)), [0, 0], [1, 3]),
    ]
    for spec, low, high in cases:
        bounds = spec_bounds(spec, 1, torch.float32)
        width = len(low)
        assert bounds[0].shape == (2, width) and bounds[0].dtype == torch.float32
        assert bounds[0][1].tolist() == low and bounds[1][1].tolist() == high
    assert spec_bounds(Unbounded(shape=(2, 3)), 1, torch.float32) is None


def test_include_current_false_keeps_only_past_steps():
    window = AdjustmentWindow(k=2, action="X", lags={"P": (0, 1, 2), "V": (0,), "X": (1, 2)}, exact=True, observed=("P", "V", "W", "X"))
    transform = CausalWindowTransform(window, include_current=False)
    assert transform.window == window.past_only()
    assert transform.window.lags == {"P": (1, 2), "X": (1, 2)}  # V had lag 0 only: gone
    assert not transform.window.exact  # the smaller sets were not checked
    assert window.past_only().past_only() == window.past_only()
    episode = TensorDict(
        {
            "P": torch.tensor([[1.0], [2.0], [3.0]]),
            "W": torch.zeros(3, 1),
            "action": torch.tensor([[10.0], [20.0], [30.0]]),
            "is_init": torch.tensor([[True], [False], [False]]),
            "next": {"P": torch.tensor([[2.0], [3.0], [4.0]]), "W": torch.zeros(3, 1)},
        },
        batch_size=[3],
    )
    # columns: P_{t-1}, P_{t-2}, X_{t-1}, X_{t-2}
    expected = torch.tensor([[0.0, 0.0, 0.0, 0.0], [1.0, 0.0, 10.0, 0.0], [2.0, 1.0, 20.0, 10.0]])
    torch.testing.assert_close(transform.encode_trajectories(episode)["observation"], expected)


def test_a_window_without_the_action_encodes_no_previous_action_and_hides_dropped_states():
    window = AdjustmentWindow(
        k=2,
        action="X",
        lags={"P": (0, 1, 2), "V": (0, 1), "X": (1, 2)},
        exact=True,
        witnesses=(),
        excluded=frozenset({"W"}),
        observed=("P", "V", "W", "X"),
    )
    no_action = window.without(["X"])
    assert no_action.lags == {"P": (0, 1, 2), "V": (0, 1)} and no_action.excluded == {"W"}
    assert not no_action.exact  # the smaller sets were not checked
    no_speed = window.without(["V"])
    assert no_speed.lags == {"P": (0, 1, 2), "X": (1, 2)} and no_speed.excluded == {"V", "W"}
    assert window.without([]) is window
    with pytest.raises(ValueError, match=r"cannot drop \['W'\]: not in the window"):
        window.without(["W", "X"])
    episode = TensorDict(
        {
            "P": torch.tensor([[1.0], [2.0], [3.0]]),
            "V": torch.tensor([[5.0], [6.0], [7.0]]),
            "W": torch.zeros(3, 1),
            "action": torch.tensor([[10.0], [20.0], [30.0]]),
            "is_init": torch.tensor([[True], [False], [False]]),
            "next": {"P": torch.tensor([[2.0], [3.0], [4.0]]), "V": torch.zeros(3, 1), "W": torch.zeros(3, 1)},
        },
        batch_size=[3],
    )
    # columns: P_t, P_{t-1}, P_{t-2}, V_t, V_{t-1}: the full window's, its action columns cut
    full = CausalWindowTransform(window).encode_trajectories(episode)["observation"]
    encoded = CausalWindowTransform(no_action).encode_trajectories(episode)
    torch.testing.assert_close(encoded["observation"], full[:, :5], rtol=0, atol=0)
    assert "action" in encoded.keys()  # the action is still what the policy outputs
    hidden = CausalWindowTransform(no_speed).encode_trajectories(episode)
    assert "V" not in hidden.keys() and "W" not in hidden.keys()


def test_causal_false_conditions_on_every_observed_variable_at_the_window_lags():
    window = AdjustmentWindow(
        k=2,
        action="X",
        lags={"P": (0, 1, 2), "X": (1, 2)},
        excluded=frozenset({"W"}),
        exact=False,
        observed=("P", "W", "X"),
    )
    twin = CausalWindowTransform(window, causal=False).window
    assert twin == window.non_causal_twin()
    assert twin.lags == {"P": (0, 1, 2), "W": (0, 1, 2), "X": (1, 2)}
    assert twin.excluded == frozenset() and not twin.exact
    sparse = AdjustmentWindow(
        k=3, action="X", lags={"P": (0, 3), "X": (2,)}, excluded=frozenset({"W"}), exact=True, observed=("P", "W", "X")
    )
    # the union of the state lags for every observed state variable, the action at 1..k
    assert sparse.non_causal_twin().lags == {"P": (0, 3), "W": (0, 3), "X": (1, 2, 3)}
    with pytest.raises(ValueError, match="observed"):
        CausalWindowTransform(AdjustmentWindow(k=1, action="X", lags={"P": (0,)}), causal=False)


# --------------------------------------------------------------------------- replay buffers


def raw_transitions(lengths=(2, 3, 4, 5), steps=12) -> TensorDictBase:
    """CountingEnv transitions as a buffer stores them: flat, each env's row in time order."""
    env = TransformedEnv(CountingEnv(lengths), InitTracker())
    return env.rollout(steps, counting_policy, break_when_any_done=False).reshape(-1)


def rows_right(batch: TensorDictBase, window: AdjustmentWindow = CAUSAL) -> int:
    """How many rows hold the closed-form encoding of their own (t, i), read back from P."""
    t, i = (batch["P"][:, 0] - 1).long().tolist(), (batch["P"][:, 1] - 1).long().tolist()
    expected = torch.stack([expected_encoding(window, a, b) for a, b in zip(t, i)])
    expected_next = torch.stack([expected_encoding(window, a + 1, b) for a, b in zip(t, i)])
    right = (batch["observation"] == expected).all(-1) & (batch["next", "observation"] == expected_next).all(-1)
    return int(right.sum())


REPLAY_SAMPLERS = {
    "random": lambda: RandomSampler(),
    "without_replacement": lambda: SamplerWithoutReplacement(),
    "slices": lambda: SliceSampler(slice_len=4, end_key=("next", "done")),
}


@pytest.mark.parametrize("sampler", list(REPLAY_SAMPLERS))
def test_replay_buffer_encodes_every_sampled_step_from_its_own_episode(sampler):
    torch.manual_seed(0)
    data = raw_transitions()
    # In place, a sample's lags would come from unrelated rows: the plain transform refuses it.
    naive = ReplayBuffer(
        storage=LazyTensorStorage(64), sampler=REPLAY_SAMPLERS[sampler](), batch_size=16, transform=CausalWindowTransform(CAUSAL)
    )
    naive.extend(data)
    with pytest.raises(RuntimeError, match="make_rb_transform_and_sample_unit"):
        naive.sample()

    transform, unit = CausalWindowTransform(CAUSAL).make_rb_transform_and_sample_unit()
    buffer = ReplayBuffer(
        storage=LazyTensorStorage(64), sampler=REPLAY_SAMPLERS[sampler](), sample_unit=unit, transform=transform, batch_size=16
    )
    buffer.extend(data)
    for _ in range(3):  # 48 stored rows: three batches (a whole epoch without replacement)
        batch, info = buffer.sample(return_info=True)
        assert batch.shape == (16,) and rows_right(batch) == 16
        assert not {"W", "latent", "scm"} & set(batch.keys())
        torch.testing.assert_close(batch["P"], data["P"][info["index"][K :: K + 1]], rtol=0, atol=0)


def test_replay_buffer_replaces_steps_whose_history_the_ring_buffer_overwrote():
    data = raw_transitions(lengths=(5,), steps=23)  # t = 0..4 repeated; the last 20 rows stay
    transform, unit = CausalWindowTransform(CAUSAL).make_rb_transform_and_sample_unit()
    buffer = ReplayBuffer(
        storage=LazyTensorStorage(20), sampler=SamplerWithoutReplacement(), sample_unit=unit, transform=transform, batch_size=20
    )
    buffer.extend(data)
    # rows 20-22 wrapped into slots 0-2: slot 2 (t = 2) is the newest, slot 3 (t = 3) the oldest
    assert buffer.storage[2]["P"][0].item() == 3 and buffer.storage[3]["P"][0].item() == 4
    batch, info = buffer.sample(return_info=True)
    assert rows_right(batch) == 20
    # Slots 3 and 4 (t = 3, 4) need t = 1, 2, which were overwritten; slot 2 before them is no predecessor.
    sampled = set(info["index"][K :: K + 1].tolist())
    assert sampled == set(range(20)) - {3, 4}

    stranded = ReplayBuffer(storage=LazyTensorStorage(8), sample_unit=unit, transform=transform, batch_size=4)
    stranded.extend(data[3:5])  # t = 3, 4: neither has its two previous steps stored
    with pytest.raises(RuntimeError, match="none of the 4 sampled steps has its 2 previous steps"):
        stranded.sample()


def test_replay_buffer_of_collector_batches_uses_the_trajectory_ids():
    from torchrl.collectors import Collector

    # 5-step episodes in 6-step batch rows: each row of the second batch continues an episode
    # (t = 1) right after the previous env's row, whose last record (t = 0) starts an episode.
    env = TransformedEnv(CountingEnv([5, 5, 5, 5]), InitTracker())
    collector = Collector(env, counting_policy, frames_per_batch=4 * 6, total_frames=4 * 12)
    transform, unit = CausalWindowTransform(CAUSAL).make_rb_transform_and_sample_unit()
    buffer = ReplayBuffer(
        storage=LazyTensorStorage(48), sampler=SamplerWithoutReplacement(), sample_unit=unit, transform=transform, batch_size=48
    )
    for batch in collector:
        buffer.extend(batch.reshape(-1))  # env rows side by side: a row's history is 24 records back
    collector.shutdown()
    batch, info = buffer.sample(return_info=True)
    assert rows_right(batch) == 48
    # second-batch steps 0, 1 of each env row continue an episode whose earlier steps are in the first batch
    t = (buffer.storage[:]["P"][:, 0] - 1).long()
    position = torch.arange(48) % 6
    cut = set(((torch.arange(48) >= 24) & (position < K) & (t > position)).nonzero().squeeze(-1).tolist())
    assert cut and set(info["index"][K :: K + 1].tolist()) == set(range(48)) - cut


def test_replay_buffer_needs_is_init_and_a_flat_storage():
    transform, unit = CausalWindowTransform(CAUSAL).make_rb_transform_and_sample_unit()
    buffer = ReplayBuffer(storage=LazyTensorStorage(64), sample_unit=unit, transform=transform, batch_size=8)
    buffer.extend(raw_transitions().exclude("is_init"))
    with pytest.raises(KeyError, match="'is_init'.*InitTracker"):
        buffer.sample()
    flat_batches = ReplayBuffer(storage=LazyTensorStorage(64, ndim=2), sample_unit=unit, transform=transform, batch_size=8)
    flat_batches.extend(raw_transitions().reshape(4, 12))
    with pytest.raises(ValueError, match="1-D storage"):
        flat_batches.sample()
    with pytest.raises(ValueError, match="windows of 3 records"):
        transform(raw_transitions()[:7])
