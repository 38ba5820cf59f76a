"""Sphinx configuration of the API reference (``make docs``; ``.ci/run`` builds it with
``-W -n``: any warning, an unresolved cross-reference included, fails the build).

The build is offline: no intersphinx inventories are fetched, so a reference to another
library's object (``torch.Tensor``, ``tensordict.TensorDictBase``) cannot resolve; those
are listed by package in ``nitpick_ignore_regex`` below, and only those. Every reference to
this package's own objects must resolve.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the checkout's package, installed or not
sys.path.insert(0, str(ROOT / "docs"))  # apihomes, this site's extension
os.environ.setdefault("OMP_NUM_THREADS", "1")

import apihomes  # noqa: E402  (after the paths above)

import torchrl_causal  # noqa: E402

project = "torchrl-causal"
author = "torchrl-causal contributors"
copyright = "torchrl-causal contributors, MIT licence"
release = version = torchrl_causal.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",  # the docstrings' Google style (Args:, Returns:, Raises:, Examples:)
    "sphinx.ext.viewcode",
    "myst_parser",  # the README, usage guide and results are Markdown
    "apihomes",  # a reference through any import path of an object resolves to its one page
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "api/generated/**/*.md"]
templates_path = ["_templates"]

# One page per module, generated at build time from the package's own ``__all__`` lists.
autosummary_generate = True
autosummary_ignore_module_all = False
autosummary_imported_members = False
autodoc_default_options = {"members": True, "show-inheritance": True}
autodoc_member_order = "bysource"
# A method without its own docstring shows none, not torch.nn.Module's (whose references need torch's inventory).
autodoc_inherit_docstrings = False
autodoc_typehints = "signature"
autodoc_class_signature = "mixed"
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_rtype = False
napoleon_attr_annotations = True
napoleon_preprocess_types = True  # "float, optional": optional is a keyword, not a class
napoleon_custom_sections = [("Class attributes", "Attributes")]  # envs/base.py's GustConfoundedEnv

myst_heading_anchors = 3
myst_enable_extensions = ["colon_fence"]

html_theme = "alabaster"
html_title = f"torchrl-causal {release}"
html_theme_options = {"description": "TorchRL components for causal imitation learning", "fixed_sidebar": True, "page_width": "1180px"}


# Each public object is documented once, on the page of its shortest import path (apihomes.py
# says how that is chosen); the other pages listing it in ``__all__`` link there.
_modules = apihomes.documented_modules()
autosummary_context = {
    "documented_modules": [module.__name__ for module in _modules],
    "pages": apihomes.members_by_page(_modules, apihomes.package_homes()),
}

# Offline: other libraries' objects cannot be resolved (no inventories), so each package is
# named here; a reference into torchrl_causal that does not resolve still fails the build.
EXTERNAL = (
    "torch",
    "torchrl",
    "tensordict",
    "numpy",
    "np",
    "omegaconf",
    "hydra",
    "gymnasium",
    "mujoco",
    "networkx",
    "matplotlib",
    "tqdm",
    "pathlib",
    "collections",
    "typing",
    "os",
    "logging",
    "dataclasses",
    "enum",
    "abc",
    "types",
    "subprocess",
    "io",
    "datetime",
    "argparse",
    "concurrent",
    "multiprocessing",
    "threading",
    "re",
    "json",
    "contextlib",
    "functools",
    "itertools",
    "signal",
    "tempfile",
    "random",
    "h5py",
    "minari",
    "wandb",
    "av",
    "imageio",
    "PIL",
    "ogbench",
    "dm_control",
    "submitit",
    "_io",
    "_thread",
    "builtins",
    "fractions",
    "numbers",
    "queue",
    "weakref",
    "shutil",
    "zipfile",
    "hashlib",
    "socket",
    "sys",
    "platform",
    "time",
    "resource",
    "gymnasium_robotics",
)
nitpicky = True
# Names of those libraries that the type hints carry unqualified (from __future__ annotations).
EXTERNAL_SHORT = (
    "Module",
    "TensorDictModule",
    "TensorDictBase",
    "TensorDict",
    "NestedKey",
    "DEVICE_TYPING",
    "EnvBase",
    "ProbabilisticTensorDictSequential",
    "WeightUpdaterBase",
    "WeightSyncScheme",
    "TensorSpec",
    "Composite",
    "DictConfig",
    "Tensor",
    "Storage",
)
nitpick_ignore_regex = [(r"py:.*", rf"{package}(\..*)?") for package in EXTERNAL] + [(r"py:class", name) for name in EXTERNAL_SHORT]
# A private base class (show-inheritance names it) is deliberately left out of the reference.
nitpick_ignore_regex.append((r"py:class", r"torchrl_causal\..*\._\w+"))
