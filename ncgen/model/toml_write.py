"""A small TOML writer for model files: tables, arrays of tables and inline values.

Only what model files need: strings, booleans, floats (``repr``, so they read back
exactly), integers, arrays and inline tables.  The output is read by :mod:`tomllib`.
"""
from __future__ import annotations

import json
import math
import re

import numpy as np

_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def key(k: str) -> str:
    """A bare key when possible, else a quoted one."""
    return k if _BARE.match(k) else json.dumps(k, ensure_ascii=False)


def value(v) -> str:
    """The TOML form of an inline value."""
    if isinstance(v, (bool, np.bool_)):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        x = float(v)
        if math.isnan(x):
            return "nan"
        if math.isinf(x):
            return "inf" if x > 0 else "-inf"
        return repr(x)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, dict):
        return "{" + ", ".join(f"{key(k)} = {value(x)}" for k, x in v.items()) + "}"
    if isinstance(v, np.ndarray):
        v = v.tolist()
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(value(x) for x in v) + "]"
    raise TypeError(f"TOML writer: no TOML form for {type(v).__name__} {v!r}")


def table(name: str, entries: dict, *, array: bool = False) -> str:
    """``[name]`` (or ``[[name]]``) followed by ``key = value`` lines."""
    head = f"[[{name}]]" if array else f"[{name}]"
    lines = [head] + [f"{key(k)} = {value(v)}" for k, v in entries.items()]
    return "\n".join(lines) + "\n"
