"""Put the benchmark tables into the README: the README's tables are generated, never typed by hand.

A table in README.md sits between two markers::

    <!-- BEGIN generated: docs/results/adaptation/adaptation.md -->
    ...
    <!-- END generated -->

and is replaced by the named file, a Markdown table a benchmark wrote (``python benchmarks/adaptation.py
--out docs/results/adaptation`` writes ``adaptation.md`` from its ``adaptation.json``). The results the
README quotes are committed under ``docs/results/`` with the JSON they came from (machine, versions,
git commit, load average).

Usage::

    python benchmarks/readme_tables.py            # rewrite README.md's generated blocks
    python benchmarks/readme_tables.py --check    # exit 1 if README.md differs from the files (CI test)
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--readme", default=str(ROOT / "README.md"))
    parser.add_argument("--check", action="store_true", help="only check; exit 1 when the README is stale")
    args = parser.parse_args(argv)
    path = Path(args.readme)
    old = path.read_text(encoding="utf-8")
    try:
        new = render(old, path.parent)
    except FileNotFoundError as exc:
        print(f"readme_tables: error: {exc}", file=sys.stderr)
        return 2
    blocks = len(BLOCK.findall(old))
    if args.check:
        if new != old:
            print(f"{path}: generated tables are stale; run python benchmarks/readme_tables.py", file=sys.stderr)
            return 1
        print(f"{path}: {blocks} generated tables up to date")
        return 0
    if new != old:
        path.write_text(new, encoding="utf-8")
    print(f"{path}: {blocks} generated tables written")
    return 0


if __name__ == "__main__":
    sys.exit(main())
