"""The documentation site in a real browser: every page opens in headless Chromium.

The site is built as the README builds it (the ``docs_site`` fixture), served on 127.0.0.1 and
every page is opened at a desktop and a phone viewport. A page fails on a console error or an
uncaught exception, a request that fails or answers >= 400, an image that does not render, a page
wider than the viewport, or a link to a page or an anchor of the site that does not exist.

Needs the ``playwright`` package (the ``dev`` extra) and a Chromium on the machine (Debian:
``apt-get install chromium``; another binary: ``SATENV_CHROMIUM=/path/to/chrome``). Playwright
drives that binary through ``executable_path``: no browser is downloaded. Without either the
test skips and says which is missing.
"""

from __future__ import annotations

import functools
import html.parser
import importlib.util
import os
import shutil
import threading
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import unquote, urldefrag, urljoin, urlsplit

import pytest

VIEWPORTS = {"desktop": (1280, 800), "phone": (390, 844)}
"""Width, height [CSS px] of the viewports every page is opened at."""
CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def chromium_path() -> str | None:
    """The Chromium binary to drive: ``SATENV_CHROMIUM``, else the first of :data:`CHROMIUM_NAMES`
    on the PATH."""
    explicit = os.environ.get("SATENV_CHROMIUM")
    if explicit:
        return explicit if os.access(explicit, os.X_OK) else None
    return next((p for p in map(shutil.which, CHROMIUM_NAMES) if p), None)


class _Ids(html.parser.HTMLParser):
    """Every ``id`` and ``name`` attribute of a page (the anchors a link may point at)."""

    def __init__(self) -> None:
        super().__init__()
        self.ids: set[str] = set()

    def handle_starttag(self, tag, attrs):
        self.ids.update(v for k, v in attrs if k in ("id", "name") and v)


@functools.cache
def _anchors(page: Path) -> frozenset[str]:
    parser = _Ids()
    parser.feed(page.read_text(encoding="utf-8"))
    return frozenset(parser.ids)


def _target_file(site: Path, path: str) -> Path | None:
    """The file of the site a URL path names (``dir/`` -> ``dir/index.html``), or ``None``."""
    rel = unquote(path).lstrip("/")
    target = site / rel
    if rel == "" or rel.endswith("/"):
        target = target / "index.html"
    elif target.is_dir():
        target = target / "index.html"
    return target if target.is_file() else None


class _QuietHandler(SimpleHTTPRequestHandler):
    def log_message(self, *args):  # the test reports failures itself
        pass


@pytest.fixture(scope="module")
def served_site(docs_site):
    site, out = docs_site
    assert out.returncode == 0, out.stdout + out.stderr
    server = ThreadingHTTPServer(("127.0.0.1", 0),
                                 functools.partial(_QuietHandler, directory=str(site)))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield site, f"http://127.0.0.1:{server.server_address[1]}/"
    server.shutdown()
    server.server_close()


def _page_problems(page, url: str, site: Path, base: str, *, full: bool = True) -> list[str]:
    """Open ``url`` in ``page`` and list what is wrong with it (``full=False``: its width only)."""
    problems: list[str] = []
    page.on("console", lambda m: problems.append(f"console {m.type}: {m.text}")
            if m.type == "error" else None)
    page.on("pageerror", lambda e: problems.append(f"uncaught exception: {e}"))
    page.on("requestfailed", lambda r: problems.append(f"request failed: {r.url} ({r.failure})"))
    page.on("response", lambda r: problems.append(f"HTTP {r.status}: {r.url}") if r.status >= 400 else None)
    page.goto(url, wait_until="load")
    width, viewport = page.evaluate("[document.documentElement.scrollWidth, window.innerWidth]")
    if width > viewport:
        problems.append(f"page is {width} px wide in a {viewport} px viewport")
    if not full:
        return problems
    broken_images = page.evaluate(
        "[...document.images].filter(i => !(i.complete && i.naturalWidth > 0)).map(i => i.src)")
    problems += [f"image not rendered: {src}" for src in broken_images]
    for href in page.evaluate("[...document.querySelectorAll('a[href]')].map(a => a.href)"):
        target, fragment = urldefrag(urljoin(url, href))
        if not target.startswith(base):
            continue  # another host: not checked (no network in tests)
        file = _target_file(site, urlsplit(target).path)
        if file is None:
            problems.append(f"broken link: {href}")
        elif fragment and file.suffix == ".html" and unquote(fragment) not in _anchors(file):
            problems.append(f"broken anchor: {href}")
    return problems


@pytest.fixture(scope="module")
def browser():
    if importlib.util.find_spec("playwright") is None:
        pytest.skip("playwright is not installed (the 'dev' extra: pip install -c constraints.txt -e '.[dev]')")
    browser_path = chromium_path()
    if browser_path is None:
        pytest.skip("no Chromium on this machine (Debian: apt-get install chromium; or set SATENV_CHROMIUM)")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        chromium = pw.chromium.launch(executable_path=browser_path, args=["--no-sandbox"])
        yield chromium
        chromium.close()


def _open_all(browser, site: Path, base: str, pages: list[str]) -> dict[str, list[str]]:
    """Problems per page and viewport: every check at the desktop size, the width at the others."""
    failures: dict[str, list[str]] = {}
    for name, (width, height) in VIEWPORTS.items():
        context = browser.new_context(viewport={"width": width, "height": height})
        for rel in pages:
            url = base + ("" if rel == "." else rel + "/")
            page = context.new_page()
            problems = _page_problems(page, url, site, base, full=name == "desktop")
            page.close()
            if problems:
                failures[f"{name} {url}"] = sorted(set(problems))
        context.close()
    return failures


def test_the_checks_catch_a_broken_page(browser, tmp_path):
    """A page with each fault is reported for each (so the site test can fail)."""
    (tmp_path / "bad").mkdir()
    (tmp_path / "index.html").write_text("<html><head><link rel='icon' href='data:,'></head>"
                                         "<body><p id='here'>ok</p><a href='bad/'>x</a></body></html>")
    (tmp_path / "bad" / "index.html").write_text(
        "<html><body><script>console.error('boom'); undefined_name();</script>"
        "<img src='missing.png'><div style='width:5000px'>wide</div>"
        "<a href='../nowhere/'>a</a><a href='../#gone'>b</a><a href='../#here'>c</a></body></html>")
    server = ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_QuietHandler, directory=str(tmp_path)))
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        base = f"http://127.0.0.1:{server.server_address[1]}/"
        failures = _open_all(browser, tmp_path, base, [".", "bad"])
    finally:
        server.shutdown()
        server.server_close()
    text = "\n".join(p for ps in failures.values() for p in ps)
    for expected in ("console error: boom", "uncaught exception", "HTTP 404", "image not rendered",
                     "px wide in a 1280 px viewport", "px wide in a 390 px viewport",
                     "broken link: " + base + "nowhere/", "broken anchor: " + base + "#gone"):
        assert expected in text, (expected, failures)
    assert "#here" not in text and not any(k.endswith(base) for k in failures), failures


def test_every_page_opens_cleanly_in_chromium(browser, served_site):
    site, base = served_site
    pages = sorted(p.parent.relative_to(site).as_posix() for p in site.glob("**/index.html"))
    assert len(pages) >= 25, pages
    failures = _open_all(browser, site, base, pages)
    assert not failures, "\n".join(f"{page}:\n  " + "\n  ".join(p) for page, p in failures.items())
