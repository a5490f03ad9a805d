"""C spellings: literals, comments and macro names used by the templates."""
from __future__ import annotations

from ncgen.errors import CodegenError


def c_real(x: float) -> str:
    """Shortest literal that reads back as the same double (``repr`` is valid C for finite x)."""
    return repr(float(x))


def c_string(s: str) -> str:
    """A C string literal for ``s`` (UTF-8, non-printable and non-ASCII bytes escaped in octal)."""
    out = []
    for b in s.encode("utf-8"):
        ch = chr(b)
        if ch in '"\\':
            out.append("\\" + ch)
        elif 32 <= b < 127 and ch != "?":  # '?' escaped to avoid trigraphs
            out.append(ch)
        else:
            out.append(f"\\{b:03o}")
    return '"' + "".join(out) + '"'


def c_comment(s: str) -> str:
    """Text safe inside a ``/* */`` comment (no comment terminator, single line)."""
    return " ".join(str(s).replace("*/", "* /").replace("/*", "/ *").split())


def wrap(items: list[str], per_line: int) -> list[str]:
    """``items`` joined by ", " in lines of ``per_line`` (each but the last ending with a comma)."""
    lines = [", ".join(items[i:i + per_line]) for i in range(0, len(items), per_line)]
    return [line + ("," if i < len(lines) - 1 else "") for i, line in enumerate(lines)]


def unique_macros(macros: list[str]) -> None:
    """Raise if two generated macro names coincide (they are upper-cased, so 'q' and 'Q' clash)."""
    seen, dup = set(), set()
    for m in macros:
        (dup if m in seen else seen).add(m)
    if dup:
        raise CodegenError(f"generated C macro names clash: {sorted(dup)}; rename the functions, "
                           f"arguments or metadata keys so that they differ ignoring case")
