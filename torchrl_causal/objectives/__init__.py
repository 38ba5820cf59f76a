"""TorchRL loss modules for (causal) imitation learning.

:class:`SQILLoss` and :class:`IQLearnLoss` are :class:`~torchrl.objectives.SACLoss`
subclasses that read a boolean ``"expert"`` flag from mixed replay batches (and, as an
option, the absorbing-state flags of :func:`add_absorbing_transitions`);
:class:`HuberBCLoss` is Causal BC; :func:`make_gail_losses` wires
:class:`GAILDiscriminatorLoss` (TorchRL's :class:`~torchrl.objectives.GAILLoss` on
logits) and TorchRL's :class:`~torchrl.objectives.ClipPPOLoss` with
:class:`DiscriminatorReward` feeding the discriminator's reward to PPO.
"""

from torchrl_causal.objectives.absorbing import ABSORBING_KEY, AbsorbingIndicator, add_absorbing_transitions
from torchrl_causal.objectives.bc import HuberBCLoss
from torchrl_causal.objectives.expert_sac import ALPHA_CLAMP, ExpertFlaggedSACLoss
from torchrl_causal.objectives.gail import (
    GAIL_REWARDS,
    DiscriminatorReward,
    GAILDiscriminatorLoss,
    GAILLosses,
    gail_discriminator_batch,
    make_gail_losses,
)
from torchrl_causal.objectives.iq_learn import IQ_LEARN_VARIANTS, IQLearnLoss
from torchrl_causal.objectives.sqil import SQILLoss
from torchrl_causal.objectives.utils import eval_mode

__all__ = [
    "ABSORBING_KEY",
    "ALPHA_CLAMP",
    "AbsorbingIndicator",
    "DiscriminatorReward",
    "ExpertFlaggedSACLoss",
    "GAILDiscriminatorLoss",
    "GAILLosses",
    "GAIL_REWARDS",
    "HuberBCLoss",
    "IQLearnLoss",
    "IQ_LEARN_VARIANTS",
    "SQILLoss",
    "add_absorbing_transitions",
    "eval_mode",
    "gail_discriminator_batch",
    "make_gail_losses",
]
