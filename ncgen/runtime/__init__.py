"""ncgen.runtime: simulation of built models.

:func:`simulate` integrates a model's index-1 DAE with IDAS (:mod:`ncgen.runtime.idas`) on
the CasADi VM or on generated C (:mod:`ncgen.runtime.dae`) and returns a
:class:`Trajectory` (:mod:`ncgen.runtime.trajectory`); how it integrates is a
:class:`SimulationOptions` (:mod:`ncgen.runtime.options`).
"""
from ncgen.runtime.options import SimulationOptions
from ncgen.runtime.simulation import simulate
from ncgen.runtime.trajectory import Trajectory

__all__ = ["SimulationOptions", "Trajectory", "simulate"]
