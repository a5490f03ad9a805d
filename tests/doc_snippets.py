"""Run the Python snippets of a Markdown page and compare what they print with the page.

A page's ```` ```python ```` blocks run section by section (a ``## `` heading starts one):
the blocks of a section in order in one namespace, each section in a fresh namespace.  A
python block followed directly by a ```` ```text ```` block must print exactly that text,
doctest-style: whitespace runs compare as one space, ``...`` matches any text (wall times,
paths), and numbers compare with a relative tolerance (``1e-3`` unless the block's info
string says ``text tol=0.05``) and an absolute one of ``1e-9``.  A python block that calls
``print`` without such a text block after it is an error (except under ``if __name__ ==
"__main__":``, which does not run here, and whose text block is compared only when the
namespace's ``__name__`` is ``"__main__"``, as tests/test_docs_sweeps.py runs docs/sweeps.md):
every printed result on a page is one a test compares.
"""
from __future__ import annotations

import contextlib
import io
import math
import re
from dataclasses import dataclass
from pathlib import Path

FENCE = re.compile(r"^```(?!`)(\w*)([^\n]*)\n(.*?)^```[ \t]*$", re.S | re.M)
NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|[-+]?(?:nan|inf)\b"
TOKEN = re.compile(rf"(\.\.\.)|({NUMBER})|(\s+)")
RTOL, ATOL = 1e-3, 1e-9


@dataclass
class Snippet:
    code: str
    line: int
    expected: str | None = None
    rtol: float = RTOL


def sections(path: Path) -> list[tuple[str, list[Snippet]]]:
    """``(heading, snippets)`` of every section of ``path`` holding python blocks (the text
    before the first ``## `` heading is the section ``"(top)"``)."""
    text = path.read_text(encoding="utf-8")
    out: list[tuple[str, list[Snippet]]] = []
    title, snippets, last_end = "(top)", [], 0
    heads = [(m.start(), m.group(1).strip()) for m in re.finditer(r"^## +(.*)$", text, re.M)]
    for m in FENCE.finditer(text):
        while heads and heads[0][0] < m.start():
            if snippets:
                out.append((title, snippets))
            title, snippets = heads.pop(0)[1], []
        lang, info, body = m.group(1), m.group(2), m.group(3)
        if lang == "python":
            snippets.append(Snippet(body, text.count("\n", 0, m.start()) + 1))
        elif lang == "text" and snippets and not text[last_end:m.start()].strip() and snippets[-1].expected is None:
            snippets[-1].expected = body
            tol = re.search(r"tol=([0-9.eE+-]+)", info)
            snippets[-1].rtol = float(tol.group(1)) if tol else RTOL
        last_end = m.end()
    if snippets:
        out.append((title, snippets))
    return out


def prints(s: Snippet) -> bool:
    """Whether the snippet prints when run here (code under ``if __name__ == "__main__":``,
    such as a process pool's, does not run in the page's namespace)."""
    return bool(re.search(r"^\s*print\(", s.code, re.M)) and "__main__" not in s.code


def run_section(where: str, snippets: list[Snippet], namespace: dict | None = None) -> dict:
    """Run ``snippets`` in one namespace; raise AssertionError naming the snippet on a failure
    or on printed output differing from the page."""
    namespace = {"__name__": "doc_snippet"} if namespace is None else namespace
    for s in snippets:
        here = f"{where}, line {s.line}"
        if prints(s) and s.expected is None:
            raise AssertionError(f"{here}: the snippet prints, but no ```text block after it shows what")
        buffer = io.StringIO()
        try:
            with contextlib.redirect_stdout(buffer):
                exec(compile(s.code, here, "exec"), namespace)
        except Exception as error:  # noqa: BLE001 - reported with the snippet
            raise AssertionError(f"{here} failed: {type(error).__name__}: {error}\n{s.code}") from error
        guarded = "__main__" in s.code and namespace.get("__name__") != "__main__"   # did not run here
        if s.expected is not None and not guarded:
            problem = compare(buffer.getvalue(), s.expected, s.rtol)
            if problem:
                raise AssertionError(f"{here}: printed output differs from the page ({problem})\n"
                                     f"--- page:\n{s.expected}--- printed:\n{buffer.getvalue()}")
    return namespace


def compare(actual: str, expected: str, rtol: float = RTOL, atol: float = ATOL) -> str | None:
    """``None`` if ``actual`` matches ``expected`` (see module docstring), else why not."""
    pattern, numbers, pos = [], [], 0
    expected = expected.strip()
    for m in TOKEN.finditer(expected):
        pattern.append(re.escape(expected[pos:m.start()]))
        if m.group(1):
            pattern.append(r".*?")
        elif m.group(2):
            pattern.append(f"({NUMBER})")
            numbers.append(m.group(2))
        else:
            pattern.append(r"\s+")
        pos = m.end()
    pattern.append(re.escape(expected[pos:]))
    match = re.fullmatch("".join(pattern), actual.strip(), re.S)
    if match is None:
        return "text differs"
    for want, got in zip(numbers, match.groups()):
        a, b = float(want), float(got)
        if math.isnan(a) and math.isnan(b):
            continue
        if not (a == b or abs(a - b) <= atol + rtol * abs(a)):
            return f"{got} printed where the page says {want} (rtol {rtol:g})"
    return None
