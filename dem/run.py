"""Command line for the DEM reference: the same as ``wheelloader dem`` (kept for old instructions).

    python dem/run.py list                              # reference cases and their commands
    python dem/run.py reference                         # regenerate all of data/reference
    python dem/run.py reference --only gravel_path1     # regenerate one case
    python dem/run.py cycle --soil dirt --path 2 --out /tmp/dirt2
    python dem/run.py sanity                            # physical sanity figures of data/reference
"""

import sys

from wheelloader.cli import main

if __name__ == "__main__":
    raise SystemExit(main(["dem", *sys.argv[1:]]))
