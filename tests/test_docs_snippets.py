"""Every Python snippet of README.md and docs/*.md runs as written and prints what the page
shows (tests/doc_snippets.py: numbers within tolerances, ``...`` for what varies).  Each
section runs in a fresh namespace, in a scratch directory where ``examples/`` is the
repository's."""
from __future__ import annotations

from pathlib import Path

import pytest

from doc_snippets import compare, prints, run_section, sections

ROOT = Path(__file__).resolve().parents[1]
#: docs/python-guide.md runs section by section in tests/test_python_guide.py.
PAGES = [ROOT / "README.md"] + sorted(p for p in (ROOT / "docs").glob("*.md") if p.name != "python-guide.md")
ALL = PAGES + [ROOT / "docs" / "python-guide.md"]
CASES = [(page, title, snippets) for page in ALL for title, snippets in sections(page)]
#: Pages in the slow tier: docs/control.md compiles its step functions and rollouts from the
#: test's empty cache (575 s at load 11 on 2 cores).
SLOW_PAGES = {"control"}
#: Every page's packages at -O0, the slow page's too (tests/conftest.py): the fast tier runs the
#: other pages so, and what a page prints does not depend on the level (round-off only).
QUICK_COMPILE = True


@pytest.fixture(autouse=True)
def scratch(tmp_path, monkeypatch):
    """The scratch directory; the compile cache is the run's (no page's output depends on what
    it holds): the contact and element libraries are compiled once for all the tests."""
    (tmp_path / "examples").symlink_to(ROOT / "examples")
    monkeypatch.chdir(tmp_path)


@pytest.mark.parametrize("page", [pytest.param(p, marks=[pytest.mark.slow, pytest.mark.timeout(1800)])
                                  if p.stem in SLOW_PAGES else p for p in PAGES if sections(p)], ids=lambda p: p.stem)
def test_page_runs_and_prints_what_it_says(page):
    """The page's snippets in order, in one namespace (later sections use earlier ones)."""
    found = sections(page)
    if "from_urdf" in "".join(s.code for _, snippets in found for s in snippets):
        pytest.importorskip("yourdfpy")
        pytest.importorskip("cmeel", reason="example-robot-data is not installed")
    namespace: dict = {"__name__": "doc_snippet"}
    for title, snippets in found:
        run_section(f"{page.relative_to(ROOT)}, section {title!r}", snippets, namespace)


def test_every_page_with_prints_shows_outputs():
    printing = [(p.name, t) for p, t, snippets in CASES for s in snippets
                if prints(s) and s.expected is None]
    assert not printing, f"snippets print without a ```text block after them: {printing}"


def test_compare_is_doctest_like():
    assert compare("nq = 4 coordinates, 3.0001 s", "nq = 4 coordinates, 3.0 s", rtol=1e-3) is None
    assert compare("nq = 4 coordinates", "nq = 12 coordinates") is not None
    assert compare("integrator: idas, 0.31 s", "integrator: idas, ...") is None
    assert compare("a   b\n c", "a b c") is None
    assert compare("energy drift", "energy balance") == "text differs"
    assert compare("1.05", "1.0", rtol=0.1) is None and compare("1.2", "1.0", rtol=0.1) is not None
