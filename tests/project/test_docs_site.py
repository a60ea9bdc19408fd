"""The documentation site (mkdocs.yml) builds with --strict, and its links and images resolve.

The build runs `mkdocs build --strict` (as `make docs` does) into a temporary folder, then a small
link checker parses every built HTML page with html.parser and follows each relative href and src:
the file must exist in the site (the site is meant to work opened from disk, so a folder link
needs its index.html; only the 404 page, which a server shows at any depth, may link from the root),
a fragment must name an id on the target page, and every image must be a non-empty PNG, SVG, JPEG
or GIF file.

The docs packages are in the `test` extra, so `make test` runs this.  Without them the build test
is skipped with the reason; with GRAINFORGE_REQUIRE_ENGINES=1 (set by .ci/run) that is a failure.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS_PACKAGES = ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python", "griffe")
IMAGE_SIGNATURES = {
    ".png": (b"\x89PNG\r\n\x1a\n",),
    ".jpg": (b"\xff\xd8\xff",),
    ".jpeg": (b"\xff\xd8\xff",),
    ".gif": (b"GIF87a", b"GIF89a"),
}


def _installed(name: str) -> bool:
    try:
        return importlib.util.find_spec(name) is not None
    except ModuleNotFoundError:  # the parent package is missing
        return False


def require_docs_packages() -> None:
    missing = [name for name in DOCS_PACKAGES if not _installed(name)]
    if missing:
        reason = f"docs packages missing ({', '.join(missing)}): pip install -e '.[docs]'"
        if os.environ.get("GRAINFORGE_REQUIRE_ENGINES") == "1":
            pytest.fail(reason + " but GRAINFORGE_REQUIRE_ENGINES=1")
        pytest.skip(reason)


class _Page(HTMLParser):
    """The ids, links (href, src) and image sources of one HTML page."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.ids: set[str] = set()
        self.links: list[tuple[str, str]] = []  # (tag, url)
        self.images: list[str] = []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        for key in ("id", "name"):
            if attrs.get(key):
                self.ids.add(attrs[key])
        for key in ("href", "src"):
            if attrs.get(key) is not None:
                self.links.append((tag, attrs[key]))
        if tag == "img" and attrs.get("src") is not None:
            self.images.append(attrs["src"])


def parse(path: Path) -> _Page:
    page = _Page()
    page.feed(path.read_text(encoding="utf-8"))
    return page


def is_external(url: str) -> bool:
    parts = urlsplit(url)
    return bool(parts.scheme or parts.netloc)


def resolve(site: Path, page: Path, url: str) -> tuple[Path | None, str]:
    """The file a relative ``url`` on ``page`` points to (None: outside the site) and its fragment."""
    parts = urlsplit(url)
    if not parts.path:
        return page, unquote(parts.fragment)
    base = page.parent
    if parts.path.startswith("/"):
        # root-absolute links break when the site is opened from disk or served under a path; only the
        # 404 page may use them (a server shows it at any depth), and then they must resolve from the root
        if page != (site / "404.html").resolve():
            return None, ""
        base = site.resolve()
    target = (base / unquote(parts.path.lstrip("/"))).resolve()
    if target.is_dir():
        target = target / "index.html"
    if site.resolve() not in target.parents and target != site.resolve():
        return None, ""
    return target, unquote(parts.fragment)


def check_site(site: Path) -> list[str]:
    """Every broken relative link, missing anchor and unreadable image of the built ``site``."""
    problems: list[str] = []
    pages = {path.resolve(): parse(path) for path in sorted(site.rglob("*.html"))}
    for path, page in pages.items():
        where = path.relative_to(site.resolve())
        for tag, url in page.links:
            if is_external(url) or url.startswith(("javascript:", "data:", "mailto:")):
                continue
            target, fragment = resolve(site, path, url)
            if target is None:
                problems.append(f"{where}: <{tag}> {url!r} leaves the site or is root-absolute")
            elif not target.is_file():
                problems.append(f"{where}: <{tag}> {url!r} -> missing file")
            elif fragment and target.suffix == ".html" and fragment not in pages[target].ids:
                problems.append(f"{where}: <{tag}> {url!r} -> no id {fragment!r} on that page")
        for url in page.images:
            if is_external(url):
                problems.append(f"{where}: image {url!r} is not in the site")
                continue
            target, _ = resolve(site, path, url)
            if target is None or not target.is_file():
                continue  # reported above as a link
            data = target.read_bytes()
            suffix = target.suffix.lower()
            if not data:
                problems.append(f"{where}: image {url!r} is empty")
            elif suffix == ".svg":
                if b"<svg" not in data[:4096]:
                    problems.append(f"{where}: image {url!r} is not SVG")
            elif suffix in IMAGE_SIGNATURES:
                if not data.startswith(IMAGE_SIGNATURES[suffix]):
                    problems.append(f"{where}: image {url!r} is not a {suffix} file")
            else:
                problems.append(f"{where}: image {url!r} has an unknown type")
    return problems


def test_checker_finds_broken_links(tmp_path):
    """The checker itself: a missing file, a missing anchor, a bad image and a root link are found."""
    (tmp_path / "img").mkdir()
    (tmp_path / "img" / "ok.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"\0" * 16)
    (tmp_path / "img" / "fake.png").write_bytes(b"not a png")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "index.html").write_text('<h2 id="here">x</h2>', encoding="utf-8")
    (tmp_path / "index.html").write_text(
        '<a href="sub/">folder</a> <a href="sub/index.html#here">ok</a> <a href="#top" id="top">self</a>'
        '<a href="https://example.org/x">external</a> <img src="img/ok.png">'
        '<a href="missing.html">1</a> <a href="sub/index.html#nowhere">2</a>'
        '<img src="img/fake.png"> <img src="img/gone.png"> <a href="/abs.html">3</a>',
        encoding="utf-8",
    )
    problems = check_site(tmp_path)
    assert len(problems) == 5, problems
    assert any("missing.html" in p and "missing file" in p for p in problems)
    assert any("'nowhere'" in p for p in problems)
    assert any("fake.png" in p and "not a .png" in p for p in problems)
    assert any("gone.png" in p and "missing file" in p for p in problems)
    assert any("/abs.html" in p and "root-absolute" in p for p in problems)


def test_sphinx_roles_become_code():
    """The API reference's griffe extension shows Sphinx roles as code spans of the shown name."""
    if not _installed("griffe"):
        pytest.skip("griffe not installed: pip install -e '.[docs]'")
    spec = importlib.util.spec_from_file_location("sphinx_roles", ROOT / "docs" / "_ext" / "sphinx_roles.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    text = (":func:`fso`, :class:`~grainforge.grain.Grain`, :mod:`.fourier`, "
            ":py:meth:`the mesh <grainforge.grain.Grain.mesh>` and ``:func:`` alone")
    assert module.rewrite_roles(text) == "`fso`, `Grain`, `.fourier`, `the mesh` and ``:func:`` alone"


@pytest.mark.slow
def test_site_builds_strict_and_links_resolve(tmp_path):
    require_docs_packages()
    site = tmp_path / "site"
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    result = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(ROOT / "mkdocs.yml"), "-d", str(site)],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert "WARNING" not in result.stderr, result.stderr

    assert check_site(site) == []

    # the landing page shows the gallery, and every page of the nav was built
    home = parse(site / "index.html")
    assert "img/gallery.png" in home.images
    for page in ("validation.html", "benchmarks.html", "changelog.html", "guide/measure.html",
                 "methods/fso.html", "design/architecture.html", "api/index.html", "api/methods-fso.html"):
        assert (site / page).is_file(), page

    # the API reference is rendered from the docstrings, numpydoc sections included, roles as code
    fso = (site / "api" / "methods-fso.html").read_text(encoding="utf-8")
    assert 'id="grainforge.methods.fso.fso"' in fso
    assert "Parameters" in fso and "Returns" in fso
    for api_page in sorted((site / "api").glob("*.html")):
        assert ":func:`" not in api_page.read_text(encoding="utf-8"), api_page.name

    # the changelog page holds CHANGELOG.md itself
    first_heading = next(line for line in (ROOT / "CHANGELOG.md").read_text(encoding="utf-8").splitlines()
                         if line.startswith("## "))
    assert first_heading[3:].strip() in (site / "changelog.html").read_text(encoding="utf-8")
