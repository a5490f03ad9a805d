"""What several subcommands share: writing text output, loading a model file."""
from __future__ import annotations

import sys
from pathlib import Path

from ncgen.errors import NcgenError
from ncgen.files import atomic_path


def write_output(text: str, path: str | None) -> None:
    """``text`` to stdout, or to ``path`` atomically (temporary file in the same directory,
    then rename), so that a failed run never leaves a truncated file."""
    if path is None or path == "-":
        sys.stdout.write(text)
        return
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    print(f"wrote {path}", file=sys.stderr)


def load_model(path: str, params: list[str] | None = None, contacts: str = "smooth", share: bool = True):
    """Build the model in TOML file ``path``; ``params`` (``name=value`` strings, a vector as
    ``name=1,2,3``) replace default parameter values.  Raises NcgenError with a message
    naming the file (and the key path, for invalid models).  ``contacts``, ``share``: as in
    ``System.build``."""
    system = load_system(path, params)
    try:
        return system.build(contacts=contacts, share=share)
    except NcgenError as e:
        raise type(e)(f"{path}: model {system.name!r} cannot be built: {e}") from None


def load_system(path: str, params: list[str] | None = None):
    """The :class:`~ncgen.model.system.System` in model file ``path`` — a URDF robot
    (``.urdf``: fixed base, joint torques as the input ``tau``) or TOML (anything else) — with
    ``params`` as in :func:`load_model`; errors name the file."""
    from ncgen.errors import ModelError
    from ncgen.model.system import System

    file = Path(path)
    if not file.is_file():
        what = "is a directory, not" if file.is_dir() else "does not exist; expected"
        raise ModelError(f"model file {path!r} {what} a TOML model file (see the examples/ directory)")
    try:
        system = System.from_urdf(file) if file.suffix.lower() == ".urdf" else System.from_toml(file)
    except NcgenError as e:
        text = str(e)
        raise type(e)(text if text.startswith(str(file)) else f"{path}: {text}") from None
    for name, value in _parameter_overrides(params or [], system):
        system.parameters[name] = (system.parameters[name][0], value)
    return system


def _parameter_overrides(params: list[str], system) -> list[tuple]:
    import numpy as np

    from ncgen.errors import ModelError

    out = []
    for item in params:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise ModelError(f"--param {item!r}: expected NAME=VALUE, e.g. --param k=50")
        if name not in system.parameters:
            known = ", ".join(system.parameters) or "none"
            raise ModelError(f"--param {item!r}: model {system.name!r} has no parameter {name!r} "
                             f"(parameters: {known})")
        size = system.parameters[name][1].size
        try:
            value = np.array([float(x) for x in text.split(",")])
        except ValueError:
            value = np.zeros(0)
        if value.size != size or not np.all(np.isfinite(value)):
            raise ModelError(f"--param {item!r}: expected {size} finite number(s) for {name!r}, "
                             f"separated by commas, got {text!r}")
        out.append((name, value))
    return out
