"""The Hydra config tree, shipped as package data (Hydra reads it as ``pkg://torchrl_causal.conf``)."""
