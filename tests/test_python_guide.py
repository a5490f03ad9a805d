"""docs/python-guide.md runs as written.

Every ```python block of the guide is executed; the blocks of one section (a ``## ``
heading) run in order in one shared namespace, each section in a fresh namespace and a
fresh temporary working directory (files the snippets write land there).  A failing
snippet fails the test with the section, the snippet's number, its text and the error.
The snippets carry their own ``assert``s on facts (closed-form periods, DOF counts, energy
conservation, ...); this file also checks that every section has some.  What a snippet
prints is compared with the ```text block after it (tests/doc_snippets.py).
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from doc_snippets import run_section, sections

GUIDE = Path(__file__).resolve().parents[1] / "docs" / "python-guide.md"
BLOCK = re.compile(r"^```python[ \t]*\n(.*?)^```[ \t]*$", re.S | re.M)


def guide_sections() -> list[tuple[str, list[str]]]:
    """``(heading, [code of each python block])`` for every ``## `` section, in order."""
    text = GUIDE.read_text(encoding="utf-8")
    parts = re.split(r"^## +", text, flags=re.M)
    return [(part.splitlines()[0].strip(), BLOCK.findall(part)) for part in parts[1:]]


SECTIONS = guide_sections()


def test_guide_has_sections_with_code_and_asserts():
    assert len(SECTIONS) >= 9, [title for title, _ in SECTIONS]
    for title, blocks in SECTIONS:
        assert blocks, f"section {title!r} has no ```python block"
        assert any(re.search(r"^\s*assert\b", code, re.M) for code in blocks), \
            f"section {title!r} checks nothing: add asserts to its snippets"


def test_no_python_block_outside_sections():
    preamble = re.split(r"^## +", GUIDE.read_text(encoding="utf-8"), flags=re.M)[0]
    assert not BLOCK.findall(preamble), "python blocks before the first '## ' section would not run"


#: Sections run in the slow tier: §6 (every integrator on compiled models) and §8 (packages generated and
#: compiled); the same calls run fast in tests/test_simulate.py, test_stepper.py and test_model_package.py.
SLOW_SECTIONS = ("6. Simulation", "8. Generated C packages")


@pytest.mark.parametrize("title, blocks", [pytest.param(t, b, marks=pytest.mark.slow) if t in SLOW_SECTIONS else (t, b)
                                           for t, b in SECTIONS], ids=[re.sub(r"\W+", "_", t).strip("_") for t, _ in SECTIONS])
def test_section_runs(title, blocks, tmp_path, monkeypatch):
    """The section's snippets run in order in one namespace and print what the guide shows
    (tests/doc_snippets.py)."""
    monkeypatch.chdir(tmp_path)
    snippets = dict(sections(GUIDE))[title]
    run_section(f"{GUIDE.name}, section {title!r}", snippets, {"__name__": f"python_guide_{len(title)}"})
