"""The README and the documentation pages: their tables are the committed benchmark results (never typed by
hand), and every code block runs as written."""

from __future__ import annotations

import importlib.util
import re
import shlex
from pathlib import Path

import pytest
from benchmark_scripts import load_benchmark

ROOT = Path(__file__).resolve().parents[1]


def test_generated_tables_are_up_to_date():
    """README.md and every result page: each generated block is its benchmark file, byte for byte."""
    tool = load_benchmark("readme_tables")
    pages = tool.pages()
    assert ROOT / "README.md" in pages and any(p.parent == ROOT / "docs" / "results" for p in pages)
    for page in pages:
        text = page.read_text(encoding="utf-8")
        assert tool.render(text) == text, f"{page.relative_to(ROOT)} is stale; run: python benchmarks/readme_tables.py"


def test_render_replaces_only_the_block(tmp_path):
    tool = load_benchmark("readme_tables")
    (tmp_path / "t.md").write_text("| a |\n|---|\n| 1 |\n")
    text = "intro\n<!-- BEGIN generated: t.md -->\nold\n<!-- END generated -->\nrest\n"
    assert tool.render(text, tmp_path) == "intro\n<!-- BEGIN generated: t.md -->\n| a |\n|---|\n| 1 |\n" \
                                          "<!-- END generated -->\nrest\n"


def test_check_names_a_stale_page(tmp_path, capsys):
    tool = load_benchmark("readme_tables")
    page = tmp_path / "page.md"
    page.write_text("<!-- BEGIN generated: docs/results/demo/table.md -->\nold\n<!-- END generated -->\n")
    assert tool.main(["--check", "--readme", str(page)]) == 1
    assert "page.md: generated tables are stale" in capsys.readouterr().err
    assert tool.main(["--readme", str(page)]) == 0 and tool.main(["--check", "--readme", str(page)]) == 0
    assert (ROOT / "docs" / "results" / "demo" / "table.md").read_text().rstrip("\n") in page.read_text()


# ---------------------------------------------------------------------------------------------------------------
# Every code block of the README and the documentation pages runs as written.
#
# Each page's blocks run in order in a fresh temporary directory of its own, laid out like a clone's root: a
# copy of data/ (the saved loop cycles of data/results only where a page reads them) and links to benchmarks/
# and dem/, with this interpreter's environment first on PATH (the installed package). Shell blocks run command
# by command; Python blocks as they stand, each in a fresh interpreter. A command listed below is not run as
# written in the default suite, for the reason given: the NOT_RUN ones never, the SLOW ones in the slow test
# (``pytest -m slow``), and in the default suite as a smoke run (the command with ``--help`` added: it starts,
# parses the options given and lists each).
# ---------------------------------------------------------------------------------------------------------------

#: The pages whose code blocks run, in this order (the README first, then the guides and the other pages).
PAGES = ["README.md", *(str(p.relative_to(ROOT)) for p in sorted((ROOT / "docs").rglob("*.md"))
                        if re.search(r"^```(bash|python)$", p.read_text(encoding="utf-8"), re.M)
                        and "/results/" not in str(p)),
         "docs/results/plant_replay.md"]
#: Other documents whose Python import lines must work (their blocks need optional extras to run).
IMPORT_ONLY = ["src/wheelloader/references/dem/README.md", "train/README.md"]

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
    'pip install -e ".[docs]" && mkdocs build --strict': "the docs build (.ci/run runs it; tests/test_docs.py)",
    "bash .ci/install_chromium.sh": "installs Chromium with apt (.ci/run does)",
    "ray start": "starts a node of a Ray cluster (several machines)",
    "python benchmarks/adaptation.py --seeds 10 --ray auto": "a sweep on a Ray cluster (several machines)",
    "python -m wheelloader.references.mpm.generate --out data/mpm --threads 2 --ray auto":
        "a sweep on a Ray cluster (several machines)",
    "python train/rllib_ppo.py --ray auto": "RLlib training on a Ray cluster (several machines)",
    "python benchmarks/paper_experiments.py --ray ray://": "Ray Client to a cluster (several machines)",
}
#: Python blocks that need an optional module (a block importing it runs only when it is installed).
PY_NEEDS = {"ray": 'pip install -e ".[scale]"',
            "stable_baselines3": 'pip install torch==2.13.0 && pip install -e ".[rl]"'}
#: Commands run as written only in the slow test (``pytest -m slow``); the default suite smoke-runs them.
SLOW = {
    "python3 -m venv .venv && . .venv/bin/activate && pip install . && wheelloader demo":
        "a fresh virtual environment and a non-editable install (test_readme_install_and_demo)",
    "python benchmarks/mpm_verification.py": "MPM simulations of minutes each",
    "wheelloader dem reference --only gravel_path1": "a Yade run of 1-4 minutes",
    "python benchmarks/paper_experiments.py": "every calibration of a reference set (minutes)",
    "python benchmarks/adaptation.py --plant": "a loop dug in a reference plant (minutes)",
    "python benchmarks/plant_first_cycle.py": "planned cycles dug in the MPM plant (minutes)",
    "wheelloader demo --plant mpm": "the demo in the MPM plant (minutes)",
    "python benchmarks/plant_replay.py": "calibrations replayed over saved loops (minutes)",
    "python benchmarks/force_models.py --fit-payload": "carves 254 saved MPM cycles (a minute or more)",
    "python benchmarks/force_model_costs.py": "times 120 000 env steps and 18 cold plans (a minute under load)",
}
#: Commands that need an optional extra to run as written: (module or executable, how to install it).
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
#: Folders under data/results a page's commands read (the saved loop cycles; copied into its workspace).
SAVED_CYCLES = {"docs/results/plant_replay.md": ["adaptation_mpm"],
                "docs/guide/force_models.md": ["adaptation_mpm", "adaptation_mpm_curlout", "adaptation_mpm_end55"]}
#: Files a page's blocks must have written (a block that silently did nothing fails here).
WRITES = {
    "README.md": ["cycle.csv", "cycle.json", "params.json", "forces.png", "plan.png", "slope.csv"],
    "docs/guide/calibration.md": ["params.json", "ms.json", "forces.png", "params3.json", "fit3.png", "my_cycle.csv",
                                  "my_cycle.json"],
    "docs/guide/planner.md": ["plan.csv", "plan.png", "slope.csv", "pareto.png"],
    "docs/guide/gym.md": ["cycle.csv", "cycle.json"],
    "docs/guide/dem.md": ["sanity.json"],
}


def _blocks(page: str) -> list[tuple[int, str, str]]:
    """(line, language, text) of every fenced code block of ``page``."""
    text = (ROOT / page).read_text(encoding="utf-8")
    return [(text[: m.start()].count("\n") + 1, m.group(1), m.group(2))
            for m in re.finditer(r"^```(\w*)\n(.*?)^```", text, re.S | re.M)]


def _commands(block: str) -> list[str]:
    """The commands of a shell block: one a line, ``\\`` continuations joined, comments dropped."""
    joined = re.sub(r"\\\n\s*", "", block)
    return [ln.strip() for ln in joined.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]


def _match(command: str, table: dict) -> str | None:
    return next((key for key in table if command.startswith(key)), None)


def _available(requirement: str) -> bool:
    import shutil

    return shutil.which(requirement) is not None or importlib.util.find_spec(requirement) is not None


def _workspace(path: Path, page: str, nlp_cache: Path) -> dict[str, str]:
    """A directory like a clone's root (data/ copied, benchmarks/ and dem/ linked) and the environment.
    Nothing the commands write can reach the checkout."""
    import os
    import shutil
    import sys

    path.mkdir(parents=True, exist_ok=True)
    shutil.copytree(ROOT / "data", path / "data", ignore=shutil.ignore_patterns("results"))
    for run in SAVED_CYCLES.get(page, []):
        shutil.copytree(ROOT / "data" / "results" / run, path / "data" / "results" / run)
    for name in ("benchmarks", "dem"):
        (path / name).symlink_to(ROOT / name, target_is_directory=True)
    env = dict(os.environ)
    env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")
    env["WHEELLOADER_NLP_CACHE"] = str(nlp_cache)  # one per test session: the planner's NLP is built once
    env["MPLBACKEND"] = "Agg"
    return env


def _run(command: str, cwd: Path, env: dict[str, str], what: str) -> str:
    import subprocess

    proc = subprocess.run(["bash", "-c", command], cwd=cwd, env=env, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, (f"{what} failed (exit status {proc.returncode}): {command}\n"
                                  f"--- stdout ---\n{proc.stdout[-3000:]}\n--- stderr ---\n{proc.stderr[-3000:]}")
    return proc.stdout


def _smoke(command: str, cwd: Path, env: dict[str, str], what: str) -> None:
    """The command with ``--help`` added: it starts, parses the options the block gives it (a bad value or
    choice before ``--help`` is an error) and lists each of them."""
    words = shlex.split(command.split(" #")[0])
    shown = _run(shlex.join([*words, "--help"]), cwd, env, what + " (smoke: --help)")
    for option in (w.split("=")[0] for w in words if w.startswith("--")):
        assert option in shown, f"{what}: {command!r} gives {option}, which its --help does not list"


def _python(block: str, cwd: Path, env: dict[str, str], what: str) -> None:
    import sys

    script = cwd.parent / f"block_{what.split()[-1]}.py"  # beside the workspace, not in it
    script.write_text(block, encoding="utf-8")
    _run(f"{sys.executable} {script}", cwd, env, what)


def test_page_blocks_are_known():
    """Every block is bash, python or text (a diagram), and every table entry above matches a page's line."""
    commands = []
    for page in PAGES:
        blocks = _blocks(page)
        assert {lang for _, lang, _ in blocks} <= {"bash", "python", "text"}, \
            [(page, line, lang) for line, lang, _ in blocks if lang not in ("bash", "python", "text")]
        commands += [c for _, lang, block in blocks if lang == "bash" for c in _commands(block)]
    for table in (NOT_RUN, SLOW, NEEDS, IN_REPO_ROOT):
        for key in table:
            assert any(c.startswith(key) for c in commands), f"no page's command starts with {key!r}"
    for page in [*SAVED_CYCLES, *WRITES]:
        assert page in PAGES, page


def _run_page(page: str, path: Path, nlp_cache: Path, slow: bool) -> int:
    """Run ``page``'s blocks in ``path``; ``slow``: the SLOW commands as written, else their smoke run. Skips
    when every block needs what is not installed."""
    env = _workspace(path, page, nlp_cache)
    ran = 0
    absent = []
    for line, lang, block in _blocks(page):
        what = f"{page} block at line {line}"
        if lang == "python":
            needs = [m for m in PY_NEEDS if re.search(rf"^\s*(import|from) {m}\b", block, re.M)]
            if any(not _available(m) for m in needs):
                absent += [f"{m} ({PY_NEEDS[m]})" for m in needs if not _available(m)]
                continue
            _python(block, path, env, what)
            ran += 1
        elif lang == "bash":
            for command in _commands(block):
                if _match(command, NOT_RUN) or command.startswith("python3 -m venv"):
                    continue  # the venv line: test_readme_install_and_demo
                if _match(command, IN_REPO_ROOT):
                    _run(command, ROOT, env, what)
                    ran += 1
                    continue
                if _match(command, SLOW) and not slow:
                    _smoke(command, path, env, what)
                    ran += 1
                    continue
                need = _match(command, NEEDS)
                if need and not _available(NEEDS[need][0]):
                    absent.append(f"{NEEDS[need][0]} ({NEEDS[need][1]})")
                    continue
                _run(command.split(" #")[0].rstrip(), path, env, what)
                ran += 1
    for expected in WRITES.get(page, []):
        assert (path / expected).is_file(), f"{page}: its blocks did not write {expected}"
    if ran == 0 and absent:
        pytest.skip(f"{page}: every block needs what is not installed: {', '.join(sorted(set(absent)))}")
    return ran


@pytest.fixture(scope="session")
def nlp_cache(tmp_path_factory):
    """The planner's NLP cache shared by the pages' commands (the first one that plans builds it)."""
    return tmp_path_factory.mktemp("nlp-cache")


@pytest.mark.parametrize("page", PAGES)
def test_every_block_runs(page, tmp_path, nlp_cache):
    """A page's shell commands and Python blocks, in order, as a new user runs them after installing (the long
    commands smoke-run: see SLOW)."""
    assert _run_page(page, tmp_path / "clone", nlp_cache, slow=False) >= 1


@pytest.mark.slow
@pytest.mark.parametrize("page", [p for p in PAGES if any(
    _match(c, SLOW) for _, lang, b in _blocks(p) if lang == "bash" for c in _commands(b))])
def test_every_block_runs_as_written(page, tmp_path, nlp_cache):
    """The pages with long commands, those too run as written."""
    assert _run_page(page, tmp_path / "clone", nlp_cache, slow=True) >= 1


def test_every_import_in_the_docs_works():
    """The import lines of the pages' Python blocks (and of the dem/ and train/ READMEs') run as written."""
    lines = []
    for doc in PAGES + IMPORT_ONLY:
        text = (ROOT / doc).read_text(encoding="utf-8")
        for block in re.findall(r"```python\n(.*?)```", text, re.S):
            lines += [ln.split("#")[0].rstrip() for ln in block.splitlines()
                      if re.match(r"(from wheelloader[\w.]* import |import wheelloader)", ln)]
    assert lines, "no import lines found"
    optional = {"stable_baselines3", "torch", "taichi", "moviepy"}  # the rl and mpm extras
    for line in lines:
        try:
            exec(line, {})  # noqa: S102 - our own docs' import lines
        except ImportError as exc:
            # a line of the optional extras' docs works once the extra is installed (its own tests check that)
            if exc.name not in optional:
                raise


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
    line, _, block = _blocks("README.md")[0]
    command = next(c for c in _commands(block) if c.startswith("python3 -m venv") and "pip install . " in c)
    env = {k: v for k, v in os.environ.items() if k != "VIRTUAL_ENV"}
    env["WHEELLOADER_NLP_CACHE"] = str(tmp_path / ".nlp-cache")
    _run(command, clone, env, f"README block at line {line}")
    assert any((clone / "wheelloader-demo").glob("*.png"))


def test_commands_not_run_as_written_in_the_default_suite():
    """Lists, as one skip with the reasons, the commands the default suite does not run as written."""
    reasons = []
    for page in PAGES:
        for _, lang, block in _blocks(page):
            for command in _commands(block) if lang == "bash" else []:
                shown = command.split(" #")[0].rstrip()
                if key := _match(command, NOT_RUN):
                    reasons.append(f"{page}: {shown}: {NOT_RUN[key]}")
                elif key := _match(command, SLOW):
                    reasons.append(f"{page}: {shown}: slow, {SLOW[key]} (smoke: --help; as written: pytest -m slow)")
                elif (key := _match(command, NEEDS)) and not _available(NEEDS[key][0]):
                    reasons.append(f"{page}: {shown}: needs {NEEDS[key][0]} ({NEEDS[key][1]})")
    assert reasons
    pytest.skip("commands not run as written here: " + "; ".join(reasons))
