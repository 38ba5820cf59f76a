"""The root of the errors this package raises on purpose.

``except TorchRLCausalError`` catches every refusal of the library (a malformed diagram, a
non-imitable one, a bad config value, a run directory of another config, a broken
checkpoint, a bad dataset, an argument out of range, a missing device or renderer) and
nothing else. Each error also keeps the built-in base it always had (``ValueError`` for bad
input, ``RuntimeError`` for a state that forbids the call, ``KeyError`` for a name nothing
holds...), so code that catches those keeps working. A refusal with a domain of its own has
its own class (:class:`~torchrl_causal.graphs.GraphError`,
:class:`~torchrl_causal.data.demonstrations.DatasetError`, ...); the others raise one of the
classes below, each the twin of a built-in. ``tests/test_errors.py`` walks every ``raise`` of
the package and holds it to this tree.

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

__all__ = [
    "ExistingFileError",
    "InvalidStateError",
    "InvalidTypeError",
    "InvalidValueError",
    "MissingAttributeError",
    "MissingDependencyError",
    "MissingFileError",
    "RenderingUnavailable",
    "TorchRLCausalError",
    "UnknownKeyError",
]


class TorchRLCausalError(Exception):
    """Base of every error torchrl-causal raises on purpose."""


class InvalidValueError(TorchRLCausalError, ValueError):
    """An argument or setting the call refuses: out of range, inconsistent with another, or unknown."""


class InvalidTypeError(TorchRLCausalError, TypeError):
    """An object of a kind the call cannot use (an env of another family, a body of another shape)."""


class RenderingUnavailable(InvalidTypeError):
    """No frames can be drawn: the env has no renderer (Route Choice), or no offscreen GL
    context opens for a MuJoCo scene (a headless machine without EGL or OSMesa). A
    ``TypeError`` too, as it always was."""


class InvalidStateError(TorchRLCausalError, RuntimeError):
    """A state that forbids the call: a device that is not there, a file that is not what it should be."""


class UnknownKeyError(TorchRLCausalError, KeyError):
    """A name or tensordict key that the registry, the data or the step does not hold."""


class MissingAttributeError(TorchRLCausalError, AttributeError):
    """An object that lacks what the call reads from it (an env without a ``causal_template``)."""


class MissingFileError(TorchRLCausalError, FileNotFoundError):
    """A file or folder the call needs that does not exist (each message says how to make it)."""


class ExistingFileError(TorchRLCausalError, FileExistsError):
    """A file or folder in the way of one the call would write (nothing is overwritten unasked)."""


class MissingDependencyError(TorchRLCausalError, ModuleNotFoundError):
    """An optional dependency that is not installed (the message names the extra that brings it)."""
