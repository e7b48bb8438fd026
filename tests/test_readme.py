"""The README's tables are the benchmark results committed under docs/results, not typed by hand."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _readme_tables():
    spec = importlib.util.spec_from_file_location("readme_tables", ROOT / "benchmarks" / "readme_tables.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_generated_tables_are_up_to_date():
    tool = _readme_tables()
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert tool.BLOCK.search(readme), "the README has no generated table"
    assert tool.render(readme) == readme, "run: python benchmarks/readme_tables.py"


def test_render_replaces_only_the_block(tmp_path):
    tool = _readme_tables()
    (tmp_path / "t.md").write_text("| a |\n|---|\n| 1 |\n")
    text = "intro\n<!-- BEGIN generated: t.md -->\nold\n<!-- END generated -->\nrest\n"
    assert tool.render(text, tmp_path) == "intro\n<!-- BEGIN generated: t.md -->\n| a |\n|---|\n| 1 |\n" \
                                          "<!-- END generated -->\nrest\n"


def test_every_import_in_the_docs_works():
    """The import lines of the README's (and the dem/ and train/ READMEs') Python blocks run as written."""
    import re

    lines = []
    for doc in ("README.md", "dem/README.md", "train/README.md"):
        text = (ROOT / doc).read_text(encoding="utf-8")
        for block in re.findall(r"```python\n(.*?)```", text, re.S):
            lines += [ln.split("#")[0].rstrip() for ln in block.splitlines()
                      if re.match(r"(from wheelloader[\w.]* import |import wheelloader)", ln)]
    assert lines, "no import lines found"
    optional = {"stable_baselines3", "torch", "taichi", "moviepy"}  # the rl and mpm extras
    for line in lines:
        try:
            exec(line, {})  # noqa: S102 - our own README's import lines
        except ImportError as exc:
            # a line of the optional extras' docs works once the extra is installed (its own tests check that)
            if exc.name not in optional:
                raise
