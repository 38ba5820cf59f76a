"""The command lines, each a thin ``main`` over library functions (no command line imports
another): ``train`` (Hydra), ``evaluate``, ``report``, ``status``, ``archive``, ``demo``,
``filmstrip`` and ``strength_ablation``. Each runs as ``python -m torchrl_causal.<command>``.
"""
