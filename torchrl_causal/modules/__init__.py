"""Networks from the paper (Appendix E) and factories wrapping them as TorchRL modules."""

from torchrl_causal.modules.factories import (
    bounded_action_spec,
    make_deterministic_actor,
    make_gail_discriminator,
    make_gail_value_network,
    make_qvalue_network,
    make_tanh_gaussian_actor,
)
from torchrl_causal.modules.networks import ResidualBlock, ResidualMLP, SkipMLP, Standardize, fit_standardizers

__all__ = [
    "ResidualBlock",
    "ResidualMLP",
    "SkipMLP",
    "Standardize",
    "bounded_action_spec",
    "fit_standardizers",
    "make_deterministic_actor",
    "make_gail_discriminator",
    "make_gail_value_network",
    "make_qvalue_network",
    "make_tanh_gaussian_actor",
]
