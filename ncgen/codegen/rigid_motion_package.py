"""The rigid-motion algebra as a C package (CasADi's C for the SX functions of
:mod:`ncgen.rigid_motion.casadi_forms`); here, not in :mod:`ncgen.rigid_motion`, so that the
algebra stays below assembly and codegen."""
from __future__ import annotations

import os

from ncgen.codegen.doc import FunctionDoc, PackageDoc
from ncgen.codegen.package import Package, write_package
from ncgen.errors import NcgenError
from ncgen.rigid_motion import casadi_forms
from ncgen.rigid_motion.numeric import C_CORE
from ncgen.symbolic.rigid_motion_forms import NAMES, form


def write_c_package(out_dir: str | os.PathLike, name: str = "ncgen_rigid_motion",
                    functions=C_CORE) -> Package:
    """Write the C package of ``functions`` (default :data:`C_CORE`) to ``out_dir``.

    The kernels are CasADi's C for the SX functions of :mod:`ncgen.rigid_motion.casadi_forms`;
    C symbol of function ``f``: ``<name>_<f>``.  Compile with
    :func:`ncgen.codegen.compile_package`, load with :func:`ncgen.codegen.load_functions`.
    """
    unknown = [n for n in functions if n not in NAMES]
    if unknown:
        raise NcgenError(f"functions: expected names among {list(NAMES)}, found unknown {unknown}")
    doc = PackageDoc(summary="Rigid-motion algebra (arboris conventions: H_ab pose of b in a, "
                             "twists [w; v], wrenches [tau; f]), generated from ncgen.symbolic.rigid_motion",
                     functions={n: FunctionDoc(purpose=form(n).doc) for n in functions})
    return write_package(name, [casadi_forms.function(n) for n in functions], out_dir, doc=doc)
