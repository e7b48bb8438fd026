"""Put the benchmark tables into the README and the result pages: their tables are generated, never typed by hand.

A table in README.md or in a page under ``docs/`` sits between two markers::

    <!-- BEGIN generated: docs/results/adaptation/adaptation.md -->
    ...
    <!-- END generated -->

and is replaced by the named file (a path from the repository's root), a Markdown table a benchmark wrote
(``python benchmarks/adaptation.py --out docs/results/adaptation`` writes ``adaptation.md`` from its
``adaptation.json``). The results are committed under ``docs/results/`` with the JSON they came from
(machine, versions, git commit, load average); each has a page ``docs/results/<name>.md``.

Usage::

    python benchmarks/readme_tables.py            # rewrite the generated blocks of README.md and docs/**/*.md
    python benchmarks/readme_tables.py --check    # exit 1 if a page differs from the files (CI test)
    python benchmarks/readme_tables.py --readme PAGE.md   # one page only
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BLOCK = re.compile(r"(<!-- BEGIN generated: (?P<source>[^ ]+) -->\n)(?P<body>.*?)(<!-- END generated -->)", re.S)


def render(readme: str, root: Path = ROOT) -> str:
    """``readme`` with every generated block replaced by its source file's text."""
    def fill(match: re.Match[str]) -> str:
        source = root / match.group("source")
        if not source.is_file():
            raise FileNotFoundError(f"README block names {match.group('source')}, which does not exist")
        return match.group(1) + source.read_text(encoding="utf-8").rstrip("\n") + "\n" + match.group(4)

    return BLOCK.sub(fill, readme)


def pages(root: Path = ROOT) -> list[Path]:
    """README.md and every Markdown page under ``docs/`` that holds a generated block."""
    found = [root / "README.md"] + sorted((root / "docs").rglob("*.md"))
    return [p for p in found if p.is_file() and BLOCK.search(p.read_text(encoding="utf-8"))]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--readme", default=None, metavar="PAGE",
                        help="only this page (default: README.md and every page under docs/ with a generated block)")
    parser.add_argument("--check", action="store_true", help="only check; exit 1 when a page is stale")
    args = parser.parse_args(argv)
    targets = [Path(args.readme)] if args.readme else pages()
    stale = 0
    blocks = 0
    for path in targets:
        old = path.read_text(encoding="utf-8")
        try:
            new = render(old)
        except FileNotFoundError as exc:
            print(f"readme_tables: error: {path}: {exc}", file=sys.stderr)
            return 2
        blocks += len(BLOCK.findall(old))
        if new == old:
            continue
        if args.check:
            print(f"{path}: generated tables are stale; run python benchmarks/readme_tables.py", file=sys.stderr)
            stale += 1
        else:
            path.write_text(new, encoding="utf-8")
            print(f"{path}: generated tables written")
    if args.check and stale:
        return 1
    print(f"{len(targets)} pages, {blocks} generated tables up to date")
    return 0


if __name__ == "__main__":
    sys.exit(main())
