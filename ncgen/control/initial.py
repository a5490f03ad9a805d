"""The initial state of a control problem judged by ``nc.simulate``'s rule: a state
``x = [q; v]`` (m, m/s) whose projection onto both constraint levels moves it by more than
``ic_tolerance`` (:class:`ncgen.runtime.options.SimulationOptions`, default 1e-6) × the
system's size is refused, naming the worst constraint, instead of being teleported."""
from __future__ import annotations

import numpy as np

from ncgen.assembly.initial_state import consistent_state
from ncgen.errors import ModelError
from ncgen.runtime.options import SimulationOptions


def check_consistent(model, x: np.ndarray, p: np.ndarray, t: float, what: str) -> None:
    """Raise :class:`ModelError` naming ``what`` when ``x`` is off the constraints at ``t``."""
    nq = model.nq
    tolerance = SimulationOptions().ic_tolerance
    try:
        consistent_state(model.functions, model.layout, model.constraint_names, x[:nq].copy(), x[nq:].copy(),
                         np.asarray(p, dtype=float), float(t), tolerance, model.M)
    except ModelError as e:
        raise ModelError(f"{what}: the state is off the constraints of {model.name!r} at t = {t:g} s: {e}. "
                         "Give a consistent state (e.g. from nc.assemble or a simulation)") from None
