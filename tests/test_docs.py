"""The documentation site: every page in its navigation, ``mkdocs build --strict`` clean, and the built API and
results pages rendered in headless Chromium without a console error.

The site needs the optional ``docs`` extra (``pip install -e ".[docs]"``) and Chromium
(``bash .ci/install_chromium.sh``: apt); without them the build and browser tests skip with that command as
the reason (``.ci/run`` installs both, and with ``CI=true`` requires them: ``WHEELLOADER_REQUIRE_DOCS=1``).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import threading
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
DOCS_INSTALL = 'pip install -e ".[docs]"'
CHROMIUM_INSTALL = "bash .ci/install_chromium.sh"
REQUIRED = os.environ.get("WHEELLOADER_REQUIRE_DOCS") == "1"


def _missing(what: str, install: str) -> None:
    if REQUIRED:
        pytest.fail(f"{what} is required here (WHEELLOADER_REQUIRE_DOCS=1); install: {install}")
    pytest.skip(f"{what} not installed: {install}")


def _nav_pages() -> list[str]:
    """The pages ``mkdocs.yml``'s nav names (paths under docs/)."""
    text = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    nav = text[text.index("\nnav:"):]
    return re.findall(r":\s*([\w/.-]+\.md)\s*$", nav, re.M)


def test_every_guide_result_and_api_page_is_in_the_navigation():
    """A page under docs/guide/, docs/api/ or a result page docs/results/<name>.md that the nav does not name
    is built but unreachable: add it to mkdocs.yml's nav."""
    pages = set(_nav_pages())
    assert pages, "mkdocs.yml has no nav"
    for page in pages:
        assert (DOCS / page).is_file(), f"mkdocs.yml's nav names {page}, which does not exist"
    wanted = [p for folder in ("guide", "api", "results") for p in sorted((DOCS / folder).glob("*.md"))]
    wanted = [p for p in wanted if p.name != "references.md"]  # a generated table, shown on the paper_mpm page
    missing = [str(p.relative_to(DOCS)) for p in wanted if str(p.relative_to(DOCS)) not in pages]
    assert not missing, f"pages missing from mkdocs.yml's nav: {missing}"


def test_readme_links_to_existing_pages():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    links = [t for t in re.findall(r"\]\(([^)\s#]+)(?:#[^)]*)?\)", readme) if not t.startswith("http")]
    assert any(t.startswith("docs/guide/") for t in links) and any(t.startswith("docs/results/") for t in links)
    for target in links:
        assert (ROOT / target).exists(), f"README links to {target}, which does not exist"


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """``mkdocs build --strict`` into a temporary folder (warnings are errors); the built site's path."""
    try:
        import mkdocs  # noqa: F401
        import mkdocstrings  # noqa: F401
    except ImportError:
        _missing("mkdocs (the docs extra)", DOCS_INSTALL)
    out = tmp_path_factory.mktemp("site")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)], cwd=ROOT,
                          capture_output=True, text=True, timeout=900, env=env)
    warnings = [ln for ln in done.stderr.splitlines() if ln.startswith(("WARNING", "ERROR"))]
    assert done.returncode == 0 and not warnings, "mkdocs build --strict failed:\n" + "\n".join(
        warnings or done.stderr.splitlines()[-30:])
    return out


def test_site_builds_with_the_api_reference_and_the_result_pages(site):
    api = (site / "api" / "estimator" / "index.html").read_text(encoding="utf-8")
    for name in ("calibrate", "CycleLog", "SoilParams", "soil_forces"):  # documented from their docstrings
        assert f'id="wheelloader.estimator.{name}"' in api, name
    assert "Parameters" in api
    for page in _nav_pages():
        built = site / page.removesuffix(".md") / "index.html" if page != "index.md" else site / "index.html"
        assert built.is_file(), f"{page} was not built"
    results = (site / "results" / "adaptation" / "index.html").read_text(encoding="utf-8")
    assert "<table>" in results and "energy per m³" in results


# ------------------------------------------------------------------ headless Chromium over the DevTools pipe
def _chromium() -> str | None:
    return next((shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)), None)


class _Browser:
    """Headless Chromium driven through the DevTools protocol on a pipe (fd 3: commands in, fd 4: events out)."""

    def __init__(self, binary: str, profile: Path) -> None:
        import queue

        to_browser_r, self._to_browser = os.pipe()
        self._from_browser, from_browser_w = os.pipe()

        def fds() -> None:  # in the child: the pipe ends on the fds Chromium reads and writes
            os.dup2(to_browser_r, 3)
            os.dup2(from_browser_w, 4)

        self.proc = subprocess.Popen(
            [binary, "--headless=new", "--no-sandbox", "--disable-gpu", "--no-first-run", "--mute-audio",
             "--remote-debugging-pipe", f"--user-data-dir={profile}", "about:blank"],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, close_fds=False,
            preexec_fn=fds)  # noqa: PLW1509 - the DevTools pipe needs fds 3 and 4 set before exec
        os.close(to_browser_r)
        os.close(from_browser_w)
        self.events: queue.Queue[dict] = queue.Queue()
        self.seen: list[dict] = []
        self._next = 0
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        buffer = b""
        while chunk := os.read(self._from_browser, 65536):
            buffer += chunk
            *messages, buffer = buffer.split(b"\0")
            for message in messages:
                self.events.put(json.loads(message))

    def send(self, method: str, params: dict | None = None, session: str | None = None) -> dict:
        """Send a command and return its result; events that arrive meanwhile are kept in ``seen``."""
        import queue

        self._next += 1
        message = {"id": self._next, "method": method, "params": params or {}}
        if session:
            message["sessionId"] = session
        os.write(self._to_browser, json.dumps(message).encode() + b"\0")
        while True:
            try:
                event = self.events.get(timeout=60)
            except queue.Empty:
                raise AssertionError(f"Chromium did not answer {method}") from None
            if event.get("id") == self._next:
                assert "error" not in event, f"{method}: {event['error']}"
                return event.get("result", {})
            self.seen.append(event)

    def wait_for(self, method: str) -> None:
        """Keep events until one named ``method`` arrives (the page's load, say)."""
        import queue

        while not any(e.get("method") == method for e in self.seen):
            try:
                self.seen.append(self.events.get(timeout=120))
            except queue.Empty:
                raise AssertionError(f"Chromium sent no {method}") from None

    def close(self) -> None:
        try:
            self.send("Browser.close")
        except (AssertionError, OSError):
            pass
        try:
            self.proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.proc.kill()


def _console_errors(events: list[dict]) -> list[str]:
    """The console errors, uncaught exceptions and failed loads among the DevTools events."""
    errors = []
    for e in events:
        method, p = e.get("method"), e.get("params", {})
        if method == "Runtime.exceptionThrown":
            errors.append("exception: " + p["exceptionDetails"].get("exception", {}).get(
                "description", p["exceptionDetails"].get("text", "")))
        elif method == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
            errors.append("console.error: " + " ".join(str(a.get("value", a.get("description", "")))
                                                       for a in p.get("args", [])))
        elif method == "Log.entryAdded" and p["entry"].get("level") == "error":
            errors.append(f"log ({p['entry'].get('source')}): {p['entry'].get('text')} {p['entry'].get('url', '')}")
    return errors


def _render(browser: _Browser, url: str) -> tuple[dict, list[str]]:
    """Open ``url`` in a new tab; the page's text, heading and table counts once loaded, and its console errors."""
    target = browser.send("Target.createTarget", {"url": "about:blank"})["targetId"]
    session = browser.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
    browser.seen = []
    for domain in ("Runtime.enable", "Log.enable", "Page.enable"):
        browser.send(domain, session=session)
    browser.send("Page.navigate", {"url": url}, session=session)
    probe = ("JSON.stringify({ready: document.readyState, title: document.title, "
             "text: document.body ? document.body.innerText.length : 0, "
             "doc: document.querySelectorAll('.doc-heading').length, "
             "tables: document.querySelectorAll('article table').length, "
             "header: (document.querySelector('.md-header') || {offsetHeight: 0}).offsetHeight})")
    browser.wait_for("Page.loadEventFired")
    # the page's deferred work (Material's search index and worker) runs after the load event: let its
    # callbacks run before the console is read
    browser.send("Runtime.evaluate", {"expression": "new Promise(r => setTimeout(r, 1000))", "awaitPromise": True},
                 session=session)
    state = json.loads(browser.send("Runtime.evaluate", {"expression": probe, "returnByValue": True},
                                    session=session)["result"]["value"])
    errors = _console_errors(browser.seen)
    browser.send("Target.closeTarget", {"targetId": target})
    return state, errors


@pytest.fixture(scope="module")
def served(site):
    """The built site over HTTP on localhost (Material's scripts need http://, not file://)."""
    import functools
    import http.server

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, *args: object) -> None:  # no line per request in the test's output
            pass

    handler = functools.partial(Quiet, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield f"http://127.0.0.1:{server.server_address[1]}"
    server.shutdown()


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    binary = _chromium()
    if binary is None:
        _missing("Chromium", CHROMIUM_INSTALL)
    b = _Browser(binary, tmp_path_factory.mktemp("chromium-profile"))
    yield b
    b.close()


def test_the_api_page_renders_in_chromium_without_console_errors(served, browser):
    state, errors = _render(browser, f"{served}/api/estimator/")
    assert not errors, errors
    assert state["ready"] == "complete" and state["title"].startswith("estimator"), state
    assert state["doc"] > 20, state  # one heading per documented object
    assert state["header"] > 0, state  # the theme's stylesheet laid the header out


def test_a_results_page_renders_in_chromium_without_console_errors(served, browser):
    state, errors = _render(browser, f"{served}/results/plant_loop/")
    assert not errors, errors
    assert state["ready"] == "complete" and state["tables"] >= 5, state


def test_a_console_error_is_caught(served, browser, site):
    """The check itself: a page that logs an error and throws is reported (so a clean page means clean)."""
    (site / "broken.html").write_text("<html><body><p>x</p><script>console.error('boom'); "
                                      "undefined_function();</script></body></html>")
    _, errors = _render(browser, f"{served}/broken.html")
    assert any("boom" in e for e in errors) and any("undefined_function" in e for e in errors), errors
