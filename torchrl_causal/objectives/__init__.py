"""TorchRL loss modules for (causal) imitation learning.

:class:`SQILLoss` and :class:`IQLearnLoss` are :class:`~torchrl.objectives.SACLoss`
subclasses that read a boolean ``"expert"`` flag from mixed replay batches;
:class:`HuberBCLoss` is Causal BC; :func:`make_gail_losses` wires TorchRL's
:class:`~torchrl.objectives.GAILLoss` and :class:`~torchrl.objectives.ClipPPOLoss`
with :class:`DiscriminatorReward` feeding the discriminator's reward to PPO.
"""

from torchrl_causal.objectives.bc import HuberBCLoss
from torchrl_causal.objectives.expert_sac import ALPHA_CLAMP, ExpertFlaggedSACLoss
from torchrl_causal.objectives.gail import DiscriminatorReward, GAILLosses, gail_discriminator_batch, make_gail_losses
from torchrl_causal.objectives.iq_learn import IQLearnLoss
from torchrl_causal.objectives.sqil import SQILLoss

__all__ = [
    "ALPHA_CLAMP",
    "DiscriminatorReward",
    "ExpertFlaggedSACLoss",
    "GAILLosses",
    "HuberBCLoss",
    "IQLearnLoss",
    "SQILLoss",
    "gail_discriminator_batch",
    "make_gail_losses",
]
