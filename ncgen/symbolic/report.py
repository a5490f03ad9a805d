"""Teaching reports: a derivation as a sequence of steps, rendered as text, Markdown or LaTeX.

A :class:`Report` is a title and a list of :class:`Step`; a step has prose and equations.
Prose may contain inline math between ``$...$`` written in LaTeX; equations are
``lhs = rhs`` pairs whose right-hand side is a SymPy object.  The LaTeX rendering is a
complete document that ``pdflatex`` compiles; in Jupyter a report renders as Markdown.
"""
from __future__ import annotations

import re
import unicodedata
from dataclasses import dataclass, field

import sympy as sp

FORMATS = ("text", "markdown", "latex")


@dataclass(frozen=True)
class Equation:
    """``lhs = rhs``; ``lhs`` is LaTeX source, ``lhs_text`` its plain-text spelling."""

    lhs: str
    rhs: object
    lhs_text: str = ""


@dataclass
class Step:
    title: str
    prose: str = ""
    equations: list[Equation] = field(default_factory=list)

    def eq(self, lhs: str, rhs, lhs_text: str = "") -> "Step":
        self.equations.append(Equation(lhs, rhs, lhs_text or latex_to_text(lhs)))
        return self


@dataclass
class Report:
    title: str
    intro: str = ""
    steps: list[Step] = field(default_factory=list)

    def step(self, title: str, prose: str = "") -> Step:
        s = Step(title, prose)
        self.steps.append(s)
        return s

    def render(self, fmt: str = "text") -> str:
        if fmt not in FORMATS:
            raise ValueError(f"report format: expected one of {', '.join(FORMATS)}, got {fmt!r}")
        return {"text": _render_text, "markdown": _render_markdown, "latex": _render_latex}[fmt](self)

    def _repr_markdown_(self) -> str:
        return self.render("markdown")

    def __str__(self) -> str:
        return self.render("text")


_TEXT_MACROS = [
    (r"\\bar\{([^{}\\])\}", "\\1\u0304"), (r"\\dot\{([^{}\\])\}", "\\1\u0307"),
    (r"\\ddot\{([^{}\\])\}", "\\1\u0308"), (r"\\hat\{([^{}\\])\}", "\\1\u0302"),
    (r"\\mathbf\{([^}]*)\}", "\\1"), (r"\\boldsymbol\{([^}]*)\}", "\\1"),
    (r"\\mathrm\{([^}]*)\}", "\\1"), (r"\\operatorname\{([^}]*)\}", "\\1"),
    (r"\\text\{([^}]*)\}", "\\1"),
    (r"\\frac\{([^}]*)\}\{([^}]*)\}", "(\\1)/(\\2)"),
]
_TEXT_SYMBOLS = {
    r"\Phi": "\u03a6", r"\phi": "\u03c6", r"\gamma": "\u03b3", r"\lambda": "\u03bb",
    r"\omega": "\u03c9", r"\tau": "\u03c4", r"\rho": "\u03c1", r"\Omega": "\u03a9",
    r"\partial": "\u2202", r"\otimes": "\u2297", r"\times": "\u00d7", r"\cdot": "\u00b7",
    r"\int": "\u222b", r"\sum": "\u03a3", r"\in": "\u2208", r"\mathbb{R}": "\u211d",
    r"\top": "\u1d40", r"^{+}": "\u207a", r"^{-1}": "\u207b\u00b9", r"\,": " ", r"\;": " ",
    r"\quad": "  ", r"\ldots": "...", r"\dots": "...", r"\le": "\u2264", r"\ge": "\u2265",
    r"\to": "\u2192", r"\mapsto": "\u21a6", r"\perp": "\u27c2", r"\theta": "\u03b8",
    r"\alpha": "\u03b1", r"\beta": "\u03b2", r"\xi": "\u03be", r"\nu": "\u03bd",
    r"\operatorname{tr}": "tr", r"\left": "", r"\right": "",
}


def latex_to_text(src: str) -> str:
    """A readable plain-text spelling of simple inline LaTeX (for the text format)."""
    out = src
    for k in sorted(_TEXT_SYMBOLS, key=len, reverse=True):
        out = out.replace(k, _TEXT_SYMBOLS[k])
    for pat, rep in _TEXT_MACROS:
        out = re.sub(pat, rep, out)
    out = out.replace("\\{", "{").replace("\\}", "}")
    out = re.sub(r"\^\{T\}|\^T", "\u1d40", out)
    out = re.sub(r"_\{([^{}]*)\}", r"_\1", out)
    out = re.sub(r"\\([A-Za-z]+)", r"\1", out)
    return out


def _width(s: str) -> int:
    """Displayed width: combining accents (x̄, ẋ) take no column."""
    return sum(not unicodedata.combining(ch) for ch in s)


def _prose_text(prose: str) -> str:
    return re.sub(r"\$([^$]+)\$", lambda m: latex_to_text(m.group(1)), prose)


def _render_text(r: Report) -> str:
    lines = [r.title, "=" * len(r.title), ""]
    if r.intro:
        lines += [_prose_text(r.intro), ""]
    for i, s in enumerate(r.steps, 1):
        head = f"{i}. {s.title}"
        lines += [head, "-" * len(head)]
        if s.prose:
            lines += [_prose_text(s.prose), ""]
        for e in s.equations:
            body = sp.pretty(e.rhs, use_unicode=True, wrap_line=False)
            blines = body.split("\n")
            lhs = (e.lhs_text or latex_to_text(e.lhs)) + " = "
            mid = len(blines) // 2
            pad = " " * _width(lhs)
            lines += [("  " + (lhs if k == mid else pad) + bl).rstrip() for k, bl in enumerate(blines)]
            lines.append("")
    return "\n".join(lines).rstrip() + "\n"


def _latex_rhs(rhs) -> str:
    if isinstance(rhs, str):
        return rhs
    return sp.latex(rhs, mat_delim="[", mat_str="matrix")


def _render_markdown(r: Report) -> str:
    lines = [f"# {r.title}", ""]
    if r.intro:
        lines += [r.intro, ""]
    for i, s in enumerate(r.steps, 1):
        lines += [f"## {i}. {s.title}", ""]
        if s.prose:
            lines += [s.prose, ""]
        for e in s.equations:
            lines += ["$$", f"{e.lhs} = {_latex_rhs(e.rhs)}", "$$", ""]
    return "\n".join(lines).rstrip() + "\n"


_PREAMBLE = r"""\documentclass[10pt]{article}
\usepackage[a4paper,landscape,margin=1.5cm]{geometry}
\usepackage{amsmath,amssymb}
\setcounter{MaxMatrixCols}{40}
\allowdisplaybreaks
\setlength{\parindent}{0pt}
\setlength{\parskip}{0.5em}
"""


def _latex_escape_text(s: str) -> str:
    """Escape LaTeX specials in prose outside ``$...$``."""
    parts = re.split(r"(\$[^$]+\$)", s)
    out = []
    for p in parts:
        if p.startswith("$"):
            out.append(p)
        else:
            for a, b in (("\\", r"\textbackslash{}"), ("&", r"\&"), ("%", r"\%"), ("#", r"\#"),
                         ("_", r"\_"), ("{", r"\{"), ("}", r"\}"), ("~", r"\textasciitilde{}"),
                         ("^", r"\textasciicircum{}")):
                p = p.replace(a, b)
            p = re.sub(r"`([^`]+)`", r"\\texttt{\1}", p)
            out.append(p)
    return "".join(out)


def _render_latex(r: Report) -> str:
    lines = [
        "% Generated by ncgen (ncgen/symbolic/report.py); do not edit.",
        _PREAMBLE.rstrip(),
        rf"\title{{{_latex_escape_text(r.title)}}}",
        r"\date{}",
        r"\begin{document}",
        r"\maketitle",
    ]
    if r.intro:
        lines += [_latex_escape_text(r.intro), ""]
    for s in r.steps:
        lines.append(rf"\section{{{_latex_escape_text(s.title)}}}")
        if s.prose:
            lines += [_latex_escape_text(s.prose), ""]
        for e in s.equations:
            body = _latex_rhs(e.rhs)
            big = isinstance(e.rhs, sp.MatrixBase) and e.rhs.shape[1] > 6
            if big:
                lines += [r"{\scriptsize", r"\[", f"{e.lhs} = {body}", r"\]", "}"]
            else:
                lines += [r"\[", f"{e.lhs} = {body}", r"\]"]
    lines.append(r"\end{document}")
    return "\n".join(lines) + "\n"
