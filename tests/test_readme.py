"""The README's tables are the benchmark results committed under docs/results, not typed by hand."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

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


# ---------------------------------------------------------------------------------------------------------------
# Every code block of the README runs as written.
#
# Shell blocks run command by command, in README order, in one temporary directory that holds a copy of data/
# and links to benchmarks/ and dem/ (the README's commands run from a clone's root), with this interpreter's
# environment first on PATH (the installed package). Python blocks run as they stand, each in a fresh
# interpreter in the same directory. A command listed below is not run as written, for the reason given;
# the tables are checked against the README, so they cannot go stale.
# ---------------------------------------------------------------------------------------------------------------

#: Commands that set up the environment the suite runs in, or are the suite itself.
NOT_RUN = {
    'python3 -m venv .venv && . .venv/bin/activate && pip install -e ".[dev]" && pytest -q -n 2':
        "the development set-up and the test suite itself (.ci/run runs exactly this)",
    'pip install -e ".[dev]"': "installs the package under test (done before the suite runs)",
    "pytest -q -n 2": "the test suite itself",
    "pytest -q -m slow": "the slow tests (pytest -m slow runs them)",
    'pip install -e ".[mpm]"': "installs the optional mpm extra (.ci/run does in CI)",
    "bash dem/install_yade.sh": "installs Yade with apt (.ci/run does in CI)",
    'pip install -e ".[scale]"': "installs the optional scale extra (.ci/run does in CI)",
    "pip install torch==2.13.0 && pip install -e \".[rllib]\"": "installs the optional rllib extra (.ci/run does)",
    "ray start": "starts a node of a Ray cluster (several machines)",
    "python benchmarks/adaptation.py --seeds 10 --ray auto": "a sweep on a Ray cluster (several machines)",
    "python -m wheelloader.references.mpm.generate --out data/mpm --threads 2 --ray auto":
        "a sweep on a Ray cluster (several machines)",
    "python train/rllib_ppo.py --ray auto": "RLlib training on a Ray cluster (several machines)",
    "python benchmarks/paper_experiments.py --ray ray://": "Ray Client to a cluster (several machines)",
}
#: Python blocks that need an optional module (a block importing it runs only when it is installed).
PY_NEEDS = {"ray": 'pip install -e ".[scale]"'}
#: Commands run only in the slow test (``pytest -m slow``), as written.
SLOW = {
    "python3 -m venv .venv && . .venv/bin/activate && pip install . && wheelloader demo":
        "a fresh virtual environment and a non-editable install (test_readme_install_and_demo)",
    "python benchmarks/mpm_verification.py": "MPM simulations of minutes each",
    "wheelloader dem reference --only gravel_path1": "a Yade run of 1-4 minutes",
}
#: Commands that need an optional extra: (module or executable, how to install it).
NEEDS = {
    "python benchmarks/mpm_verification.py": ("taichi", 'pip install -e ".[mpm]"'),
    "wheelloader dem reference": ("yade", "bash dem/install_yade.sh"),
    "python benchmarks/adaptation.py --plant mpm": ("taichi", 'pip install -e ".[mpm]"'),
    "python benchmarks/adaptation.py --plant dem": ("yade", "bash dem/install_yade.sh"),
    "python benchmarks/plant_first_cycle.py": ("taichi", 'pip install -e ".[mpm]"'),
    "wheelloader demo --plant mpm": ("taichi", 'pip install -e ".[mpm]"'),
}
#: Read-only commands about the checkout itself: run in the repository root.
IN_REPO_ROOT = {"ruff check .": "lints the checkout"}
#: Long benchmarks: the default suite runs them with these arguments added (the slow test as written).
FAST_VARIANT = {
    "python benchmarks/paper_experiments.py": " --methods default",
}


def _blocks() -> list[tuple[int, str, str]]:
    """(line, language, text) of every fenced code block of the README."""
    import re

    text = (ROOT / "README.md").read_text(encoding="utf-8")
    return [(text[: m.start()].count("\n") + 1, m.group(1), m.group(2))
            for m in re.finditer(r"^```(\w*)\n(.*?)^```", text, re.S | re.M)]


def _commands(block: str) -> list[str]:
    return [ln.strip() for ln in block.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]


def _match(command: str, table: dict) -> str | None:
    return next((key for key in table if command.startswith(key)), None)


def _available(requirement: str) -> bool:
    import importlib.util
    import shutil

    return shutil.which(requirement) is not None or importlib.util.find_spec(requirement) is not None


def _workspace(path: Path) -> dict[str, str]:
    """A directory like a clone's root (data/ and the shipped MPM loop cycles copied, benchmarks/ and dem/
    linked) and the environment. Nothing the commands write can reach the checkout's docs/."""
    import os
    import shutil
    import sys

    shutil.copytree(ROOT / "data", path / "data", ignore=shutil.ignore_patterns("results"))
    cycles = Path("data") / "results" / "adaptation_mpm" / "cycles"  # read by benchmarks/plant_replay.py
    shutil.copytree(ROOT / cycles, path / cycles)
    for name in ("benchmarks", "dem"):
        (path / name).symlink_to(ROOT / name, target_is_directory=True)
    env = dict(os.environ)
    env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")
    env["WHEELLOADER_NLP_CACHE"] = str(path / ".nlp-cache")
    env["MPLBACKEND"] = "Agg"
    return env


def _run(command: str, cwd: Path, env: dict[str, str], what: str) -> None:
    import subprocess

    proc = subprocess.run(["bash", "-c", command], cwd=cwd, env=env, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, (f"{what} failed (exit status {proc.returncode}): {command}\n"
                                  f"--- stdout ---\n{proc.stdout[-3000:]}\n--- stderr ---\n{proc.stderr[-3000:]}")


def _python(block: str, cwd: Path, env: dict[str, str], what: str) -> None:
    import sys

    script = cwd.parent / f"readme_block_{what.split()[-1]}.py"  # beside the workspace, not in it
    script.write_text(block, encoding="utf-8")
    _run(f"{sys.executable} {script}", cwd, env, what)


def test_readme_blocks_are_known():
    """Every block is bash, python or text (a diagram), and every table entry above matches a README line."""
    blocks = _blocks()
    assert blocks and {lang for _, lang, _ in blocks} <= {"bash", "python", "text"}, \
        [(line, lang) for line, lang, _ in blocks if lang not in ("bash", "python", "text")]
    commands = [c for _, lang, block in blocks if lang == "bash" for c in _commands(block)]
    for table in (NOT_RUN, SLOW, NEEDS, IN_REPO_ROOT, FAST_VARIANT):
        for key in table:
            assert any(c.startswith(key) for c in commands), f"no README command starts with {key!r}"


def _run_readme(path: Path, slow: bool) -> int:
    """Run the README's blocks in ``path``; ``slow``: also the slow commands, and benchmarks as written."""
    import re

    env = _workspace(path)
    ran = 0
    for line, lang, block in _blocks():
        what = f"README block at line {line}"
        if lang == "python":
            needs = [m for m in PY_NEEDS if re.search(rf"^\s*(import|from) {m}\b", block, re.M)]
            if any(not _available(m) for m in needs):
                continue
            _python(block, path, env, what)
            ran += 1
        elif lang == "bash":
            for command in _commands(block):
                if _match(command, NOT_RUN) or command.startswith("python3 -m venv"):
                    continue  # the venv line: test_readme_install_and_demo
                if _match(command, SLOW) and not slow:
                    continue
                need = _match(command, NEEDS)
                if need and not _available(NEEDS[need][0]):
                    continue
                if _match(command, IN_REPO_ROOT):
                    _run(command, ROOT, env, what)
                    ran += 1
                    continue
                fast = _match(command, FAST_VARIANT)
                extra = FAST_VARIANT[fast] if fast and not slow else ""
                _run(command.split("#")[0].rstrip() + extra, path, env, what)
                ran += 1
    for expected in ("params.json", "ms.json", "forces.png", "plan.png", "slope.csv", "pareto.png", "cycle.csv",
                     "cycle.json", "sanity.json"):
        assert (path / expected).is_file(), expected
    return ran


def test_every_readme_block_runs(tmp_path):
    """The README's shell commands and Python blocks, in order, as a new user runs them after installing."""
    (tmp_path / "clone").mkdir()
    assert _run_readme(tmp_path / "clone", slow=False) >= 13


@pytest.mark.slow
def test_every_readme_block_runs_as_written(tmp_path):
    """The same with the long commands too, and the benchmarks without their fast variant."""
    (tmp_path / "clone").mkdir()
    assert _run_readme(tmp_path / "clone", slow=True) >= 13


@pytest.mark.slow
def test_readme_install_and_demo(tmp_path):
    """The README's first command, verbatim, in a copy of the checkout's files: a fresh venv, ``pip install .``
    (a non-editable install) and ``wheelloader demo``."""
    import os
    import shutil
    import subprocess

    files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard"], cwd=ROOT, capture_output=True,
                           text=True, check=True).stdout.split("\n")
    clone = tmp_path / "clone"
    for name in filter(None, files):
        if (ROOT / name).is_file():
            (clone / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, clone / name)
    line, _, block = _blocks()[0]
    command = next(c for c in _commands(block) if c.startswith("python3 -m venv") and "pip install . " in c)
    env = {k: v for k, v in os.environ.items() if k != "VIRTUAL_ENV"}
    env["WHEELLOADER_NLP_CACHE"] = str(tmp_path / ".nlp-cache")
    _run(command, clone, env, f"README block at line {line}")
    assert any((clone / "wheelloader-demo").glob("*.png"))


def test_readme_commands_not_run_in_the_default_suite():
    """Lists, as one skip with the reasons, the README commands the default suite does not run as written."""
    reasons = []
    for _, lang, block in _blocks():
        for command in _commands(block) if lang == "bash" else []:
            shown = command.split("#")[0].rstrip()
            if key := _match(command, NOT_RUN):
                reasons.append(f"{shown}: {NOT_RUN[key]}")
            elif key := _match(command, SLOW):
                reasons.append(f"{shown}: slow, {SLOW[key]} (pytest -m slow)")
            elif (key := _match(command, NEEDS)) and not _available(NEEDS[key][0]):
                reasons.append(f"{shown}: needs {NEEDS[key][0]} ({NEEDS[key][1]})")
            elif key := _match(command, FAST_VARIANT):
                reasons.append(f"{shown}: run with{FAST_VARIANT[key]} (as written: pytest -m slow)")
    assert reasons
    pytest.skip("README commands not run as written here: " + "; ".join(reasons))
