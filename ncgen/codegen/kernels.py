"""CasADi's C code for a list of functions, split into translation units.

Each function ``f`` of package ``name`` is exported in C as ``<name>_<f>`` (so several
packages can be linked into one program).  Functions are packed, in the order given, into
files ``<name>_kernels_<k>.c`` holding at most ``max_file_instructions`` instructions each
(SX instructions; an MX function that cannot be expanded counts its MX nodes; a larger
function gets a file of its own), so big models compile file by file, in parallel, with
bounded memory.  ``None`` puts everything in one file, ``0`` one function
per file.
"""
from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import casadi as ca

from ncgen.codegen.reroll import reroll
from ncgen.errors import CodegenError

#: CodeGenerator options ncgen relies on; callers may add others but not change these.
FIXED_CASADI_OPTIONS = {"with_header": True, "main": False, "mex": False, "cpp": False}
#: Functions named so are C functions of their own, called (never inlined) by the MX
#: functions that use them, whose constant arguments stay arrays: the contact pair kinds
#: (:mod:`ncgen.assembly.pair_kinds`), and the MPC's stage kernels, which its QP data call at
#: every interval of the horizon (:func:`ncgen.control.mpc.stage_function`).
CALLED_PREFIXES = ("pk_", "mpc_stage")
#: Defaults the caller may override.
DEFAULT_CASADI_OPTIONS = {"casadi_real": "double", "verbose": False}


@dataclass(frozen=True)
class KernelFile:
    """One CasADi translation unit: its file stem, the functions in it and the C text."""

    stem: str
    functions: tuple[str, ...]
    c_code: str
    h_code: str


def c_function(f: ca.Function, c_name: str, reroll_instructions: int | None = None) -> ca.Function:
    """``f`` named ``c_name``, same values, in the form CasADi generates C from.

    Expanded to an SX function when possible.  Longer than ``reroll_instructions`` SX
    instructions (``None``: never), an SX function is rerolled
    (:func:`ncgen.codegen.reroll.reroll`: loops over short kernels instead of straight-line
    code) and an MX function stays MX (a wrapper calling ``f``: its calls, rerolled
    functions say, are generated as they are).  An MX function with nodes SX cannot
    evaluate (a linear solver such as ``solve(K, b, "qr")``) stays MX too, and so does one that
    calls a function of :data:`CALLED_PREFIXES`."""
    if f.has_free():
        free = f.free_sx() if f.is_a("SXFunction") else f.free_mx()
        raise CodegenError(f"function {f.name()!r} has free symbols {[str(s) for s in free]}; "
                           f"make them inputs before generating C")
    if f.is_a("MXFunction") and any(g.name().startswith(CALLED_PREFIXES) for g in f.find_functions()):
        return _wrapper(f, c_name)
    try:
        e = f.expand(c_name)
    except RuntimeError as err:
        if not (f.is_a("MXFunction") and "eval_sx not defined" in str(err)):
            raise CodegenError(f"function {f.name()!r} cannot be turned into an SX function for "
                               f"code generation: {str(err).strip().splitlines()[-1]}") from None
        return _wrapper(f, c_name)
    if reroll_instructions is None or e.n_instructions() <= reroll_instructions:
        return e
    return _wrapper(f, c_name) if f.is_a("MXFunction") else reroll(e)


def _wrapper(f: ca.Function, c_name: str) -> ca.Function:
    args = f.mx_in()
    return ca.Function(c_name, args, f.call(args), f.name_in(), f.name_out())


def max_function_size(f: ca.Function) -> int:
    """Instructions of the longest C function generated for ``f``: ``f`` itself (SX
    instructions, or MX nodes) or any function it embeds (a system Jacobian, an MX wrapper,
    counts a few nodes but calls SX functions of tens of thousands of instructions)."""
    def own(g):
        return g.n_instructions() if g.is_a("SXFunction") or g.is_a("MXFunction") else 0
    return max([own(f)] + [own(g) for g in f.find_functions(-1)])


def group_functions(functions: Sequence[ca.Function], max_file_instructions: int | None) -> list[list[int]]:
    """Indices of ``functions`` packed in order into groups of bounded instruction count."""
    if max_file_instructions is None:
        return [list(range(len(functions)))] if functions else []
    if max_file_instructions < 0:
        raise CodegenError(f"max_file_instructions must be None or >= 0, found {max_file_instructions}")
    groups: list[list[int]] = []
    size = 0
    for i, f in enumerate(functions):
        n = f.n_instructions()
        if not groups or size + n > max_file_instructions:
            groups.append([])
            size = 0
        groups[-1].append(i)
        size += n
    return groups


def casadi_options(extra: Mapping | None) -> dict:
    """CodeGenerator options: defaults, then ``extra``; the fixed ones cannot be overridden."""
    extra = dict(extra or {})
    clash = sorted(k for k in extra if k in FIXED_CASADI_OPTIONS and extra[k] != FIXED_CASADI_OPTIONS[k])
    if clash:
        raise CodegenError(f"casadi_options may not change {clash}: ncgen needs {FIXED_CASADI_OPTIONS}")
    return {**DEFAULT_CASADI_OPTIONS, **extra, **FIXED_CASADI_OPTIONS}


def generate_kernels(name: str, functions: Sequence[ca.Function], groups: list[list[int]],
                     options: Mapping) -> list[KernelFile]:
    """Run CasADi's CodeGenerator once per group; ``functions`` already carry their C names."""
    files = []
    with tempfile.TemporaryDirectory(prefix="ncgen-casadi-") as tmp:
        for k, group in enumerate(groups):
            stem = f"{name}_kernels_{k}"
            cg = ca.CodeGenerator(stem + ".c", dict(options))
            for i in group:
                cg.add(functions[i])
            cg.generate(tmp + "/")
            c_code = Path(tmp, stem + ".c").read_text()
            h_code = Path(tmp, stem + ".h").read_text()
            files.append(KernelFile(stem, tuple(functions[i].name() for i in group), c_code, h_code))
    return files
