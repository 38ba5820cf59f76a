"""The documentation site's page list: every Markdown page of ``docs/`` is reachable.

A page left out of the root toctree is built but linked from nowhere (Sphinx warns, and
``make docs`` fails on any warning); this catches it without running Sphinx.
"""

import re
from pathlib import Path

DOCS = Path(__file__).resolve().parents[1] / "docs"


def _toctree_entries(index: str) -> list[str]:
    """The entries of the MyST ``{toctree}`` blocks of ``index`` (options and blanks skipped)."""
    entries = []
    for block in re.findall(r"```\{toctree\}\n(.*?)```", index, flags=re.DOTALL):
        entries += [line.strip() for line in block.splitlines() if line.strip() and not line.startswith(":")]
    return entries


def test_toctree_lists_every_page() -> None:
    entries = _toctree_entries((DOCS / "index.md").read_text(encoding="utf-8"))
    pages = {path.stem for path in DOCS.glob("*.md")} | {path.stem for path in DOCS.glob("*.rst")}
    assert entries, "docs/index.md has no toctree entries"
    assert len(entries) == len(set(entries)), f"a page is listed twice: {entries}"
    assert set(entries) == pages - {"index"}, (
        f"unlisted pages: {sorted(pages - {'index'} - set(entries))}; listed but missing: {sorted(set(entries) - pages)}"
    )
