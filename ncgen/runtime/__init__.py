"""ncgen.runtime: simulation of built models.

:func:`simulate` integrates a model's index-1 DAE with IDAS (:mod:`ncgen.runtime.idas`) on
the CasADi VM or on generated C (:mod:`ncgen.runtime.dae`) and returns a
:class:`Trajectory` (:mod:`ncgen.runtime.trajectory`).
"""
from ncgen.runtime.simulation import simulate
from ncgen.runtime.trajectory import Trajectory

__all__ = ["Trajectory", "simulate"]
