"""Optional dependencies and the extras that install them.

A feature that needs a package outside the core dependencies asks :func:`require_extra`
for it at the moment it is used, or :func:`missing_extra` while checking a config (so
that a run fails before its run directory exists), and the error names the one
``pip install`` line that fixes it.
"""

from __future__ import annotations

import importlib
import importlib.util
from types import ModuleType

from torchrl_causal.errors import MissingDependencyError, UnknownKeyError

__all__ = ["EXTRAS", "install_line", "missing_extra", "require_extra"]

# module -> the extra of pyproject.toml that installs it
EXTRAS: dict[str, str] = {
    "minari": "minari",
    "h5py": "minari",
    "tensorboard": "tensorboard",
    "wandb": "wandb",
    "av": "video",
    "imageio": "video",
    "hydra_plugins.hydra_submitit_launcher": "cluster",
}


def install_line(module: str) -> str:
    """The command that installs ``module``.

    Examples:
        >>> install_line("wandb")
        "pip install 'torchrl-causal[wandb]'"
    """
    if module not in EXTRAS:
        raise UnknownKeyError(f"{module!r} is not an optional dependency; known: {sorted(EXTRAS)}")
    return f"pip install 'torchrl-causal[{EXTRAS[module]}]'"


def _importable(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a parent package missing, or a module set to None in sys.modules
        return False


def missing_extra(purpose: str, *modules: str) -> str | None:
    """``None`` when every module imports, else a one-line message: what ``purpose`` needs
    and the command that installs it.

    Examples:
        >>> import sys
        >>> missing_extra("logger=csv") is None  # no module needed
        True
        >>> saved = sys.modules.pop("wandb", None)
        >>> sys.modules["wandb"] = None  # as if it were not installed
        >>> missing_extra("logger=wandb", "wandb")
        "logger=wandb needs wandb, which is not installed: pip install 'torchrl-causal[wandb]'"
        >>> del sys.modules["wandb"]
        >>> if saved is not None:
        ...     sys.modules["wandb"] = saved
    """
    for module in modules:
        install_line(module)  # an unknown module is a programming error, raised whether or not it imports
    absent = [module for module in modules if not _importable(module)]
    if not absent:
        return None
    return f"{purpose} needs {' and '.join(absent)}, which is not installed: {install_line(absent[0])}"


def require_extra(purpose: str, module: str) -> ModuleType:
    """Imports ``module``; raises :class:`ImportError` naming the extra when it is missing.

    Raises:
        ImportError: ``module`` is not installed (``missing_extra``'s message).
    """
    message = missing_extra(purpose, module)
    if message:
        raise MissingDependencyError(message)
    return importlib.import_module(module)
