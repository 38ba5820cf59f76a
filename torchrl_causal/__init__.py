"""torchrl-causal: TorchRL components for causal imitation learning under unobserved confounding.

Layout (arrows only point down): ``graphs`` (pure Python causal machinery) →
``envs`` → ``transforms`` → ``modules`` → ``objectives`` → ``data`` → ``trainers`` →
``evaluation``. Causal knowledge enters training through one door: the
:class:`~torchrl_causal.graphs.AdjustmentWindow` that ``graphs`` computes and
:class:`~torchrl_causal.transforms.CausalWindowTransform` applies.
"""

__version__ = "0.1.0"
