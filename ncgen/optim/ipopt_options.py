"""IPOPT options checked where they enter (``OptimalControl.solve(ipopt=...)``, ``[solver.ipopt]``
of problem files), by IPOPT itself: the options are handed to a solver of a one-variable
problem, and when IPOPT refuses them, each is tried alone so that the message names the one
it refused and quotes IPOPT's reason (no such option, wrong type, value out of range or not
one of the valid settings).  Values must be numbers (finite) or strings."""
from __future__ import annotations

import contextlib
import ctypes
import io
import math
import os
import sys
import tempfile

import casadi as ca

from ncgen.errors import OptimizationError


def check_ipopt_options(options, where: str = "ipopt") -> dict:
    """``options`` as a dict after the checks of the module docstring; raises
    :class:`~ncgen.errors.OptimizationError` naming ``where`` and the option."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise OptimizationError(f"{where}: expected a dict of IPOPT options, got {type(options).__name__}")
    for key, value in options.items():
        if not isinstance(key, str) or not key:
            raise OptimizationError(f"{where}: option names are strings, got {key!r}")
        if isinstance(value, bool) or not isinstance(value, (int, float, str)):
            raise OptimizationError(f"{where}.{key}: expected a number or a string (IPOPT's yes/no options take "
                                    f"'yes' or 'no'), got {type(value).__name__} {value!r}")
        if isinstance(value, float) and not math.isfinite(value):
            raise OptimizationError(f"{where}.{key}: expected a finite number, got {value!r}")
    if options and _refusal(options) is not None:
        for key, value in options.items():
            reason = _refusal({key: value})
            if reason is not None:
                raise OptimizationError(f"{where}.{key} = {value!r}: IPOPT refuses it: {reason}")
        raise OptimizationError(f"{where}: IPOPT refuses these options together: {options!r}")
    return dict(options)


def _refusal(options: dict) -> str | None:
    """IPOPT's reason for refusing ``options`` (None when it accepts them)."""
    x = ca.SX.sym("x")
    settings = {"print_level": 0, "sb": "yes", **options}
    with _captured_stdout() as printed:
        try:
            ca.nlpsol("ncgen_option_probe", "ipopt", {"x": x, "f": x * x},
                      {"print_time": False, "ipopt": settings})
            return None
        except RuntimeError as e:
            said = str(e)
        text = printed()
    lines = text.splitlines()
    for k, line in enumerate(lines):
        if line.startswith("Setting:"):
            valid = [ln.strip().split(" ")[0] for ln in lines[k:] if ln.startswith("\t")]
            bounds = [ln.strip() for ln in lines[k:] if "<" in ln and "(" in ln]
            found = line.strip().split(" Check the option")[0]
            if valid:
                return f"{found} Valid settings: {', '.join(valid)}"
            return f"{found} Valid range: {bounds[0]} (default in parentheses)" if bounds else found
    if "No such IPOPT option" in said:
        return "no such option (see IPOPT's option list)"
    if "type mismatch" in said:
        return "wrong type (IPOPT expects a number here, or a string, as its documentation says)"
    return said.strip().splitlines()[-1]


def _flush_c_stdio() -> None:
    """Flush C's stdio buffers (block-buffered when stdout is a file)."""
    ctypes.CDLL(None).fflush(None)


@contextlib.contextmanager
def _captured_stdout():
    """Capture what IPOPT prints (its option documentation), whether CasADi routes it through
    Python's ``sys.stdout`` or C writes it on file descriptor 1."""
    sys.stdout.flush()
    saved = os.dup(1)
    python_side = io.StringIO()
    with tempfile.TemporaryFile(mode="w+b") as f, contextlib.redirect_stdout(python_side):
        os.dup2(f.fileno(), 1)
        try:
            yield lambda: (_flush_c_stdio(), f.seek(0), f.read().decode("utf-8", "replace"))[2] + python_side.getvalue()
        finally:
            _flush_c_stdio()
            os.dup2(saved, 1)
            os.close(saved)
