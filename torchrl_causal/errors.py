"""The root of the errors this package raises on purpose.

``except TorchRLCausalError`` catches every refusal of the library (a malformed diagram, a
non-imitable one, a bad config value, a run directory of another config, a broken
checkpoint, a bad dataset) and nothing else. Each error also keeps the built-in base it
always had (``ValueError`` for bad input, ``RuntimeError`` for a state that forbids the
call), so code that catches those keeps working.

:class:`~torchrl_causal.experiment.interrupts.RunInterrupted` is no error (a requested
stop, carried to the top by an exception) and stays outside this tree.

Examples:
    >>> from torchrl_causal.graphs import CausalDiagram, GraphError
    >>> try:
    ...     CausalDiagram([("a", "b"), ("b", "a")])
    ... except TorchRLCausalError as error:
    ...     print(type(error).__name__, isinstance(error, (GraphError, ValueError)))
    GraphError True
"""

from __future__ import annotations

__all__ = ["TorchRLCausalError"]


class TorchRLCausalError(Exception):
    """Base of every error torchrl-causal raises on purpose."""
