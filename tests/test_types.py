"""``mypy`` (configured in ``pyproject.toml``) passes on the whole package, and no module is
exempt from it: no ``ignore_errors`` override, no file-wide ``# mypy: ignore-errors``, and
every ``# type: ignore`` names the error code it silences."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10: mypy itself depends on tomli there
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "torchrl_causal"


def test_mypy_finds_nothing() -> None:
    done = subprocess.run([sys.executable, "-m", "mypy"], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr


def test_no_module_is_exempt_from_the_check() -> None:
    settings = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["mypy"]
    assert settings["files"] == ["torchrl_causal"]
    assert not {"ignore_errors", "disable_error_code"} & set(settings), "mypy's settings switch checks off package-wide"
    exempt = [module for override in settings.get("overrides", []) if override.get("ignore_errors") for module in override["module"]]
    assert not exempt, f"fix these modules' type errors instead of exempting them: {exempt}"
    sources = {path.relative_to(ROOT).as_posix(): path.read_text() for path in PACKAGE.rglob("*.py")}
    assert len(sources) > 50
    file_wide = [path for path, text in sources.items() if re.search(r"#\s*mypy:\s*ignore-errors", text)]
    assert not file_wide, f"file-wide ignore-errors in {file_wide}"
    bare = [
        f"{path}:{number}"
        for path, text in sources.items()
        for number, line in enumerate(text.splitlines(), 1)
        if re.search(r"#\s*type:\s*ignore(?!\[)", line)
    ]
    assert not bare, f"a # type: ignore without an error code silences everything on its line: {bare}"
