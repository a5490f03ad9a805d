"""The optional ``linearize`` kernel of a model package (``generate(..., linearization=True)``):
the minimal-state linearisation of :mod:`ncgen.assembly.linearization_function` as generated C, for
LQR/MPC code that re-linearises without Python.  The caller passes the tangent basis ``N``
and the coordinates ``G`` (``A N = 0``, ``G N = I``), e.g. computed once by
``nc.linearize`` (``lin.N``, ``lin.G``) and kept while the state stays near."""
from __future__ import annotations

from ncgen.assembly.linearization_function import DOC, linearization_function
from ncgen.assembly.mass import sparse_dm
from ncgen.codegen.section import Section


def linearization_section(model, reroll_instructions=None):
    """A :class:`~ncgen.codegen.section.Section` holding ``linearize``."""
    f = linearization_function(model.functions, sparse_dm(model.M), model.dof)
    return Section(functions=[f], docs={"linearize": DOC})
