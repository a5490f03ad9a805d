"""ncgen.analysis: what a model does at and near a state, from its CasADi functions.

Static equilibrium and its stability (:mod:`~ncgen.analysis.statics`), vibration modes
(:mod:`~ncgen.analysis.modes`), linearisation (:mod:`~ncgen.analysis.linearization`),
form-finding of tensegrities (:mod:`~ncgen.analysis.formfinding`) and joint reactions
from the multipliers (:mod:`~ncgen.analysis.reactions`).  Above runtime: a mode's motion
is returned as a :class:`~ncgen.runtime.trajectory.Trajectory`.
"""
