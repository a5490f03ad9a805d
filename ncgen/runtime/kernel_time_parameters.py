"""Time and parameters of a compiled tree kernel's later calls (one rule for every kernel class).

A kernel's :class:`~ncgen.codegen.direct.DirectFunction` takes the time ``t`` (s) as its first
input and the parameters ``p`` (``model.parameter_names`` order) as its last; both stay in the
input buffers between calls, so a call writes them only when they change.
"""
from __future__ import annotations

from ncgen.validation import as_vector


class TimeAndParameters:
    """Mixin of a kernel with ``model``, ``direct`` (its DirectFunction) and ``_p`` (the
    parameter input buffer): :meth:`set` and the per-call :meth:`_at`."""

    def set(self, *, t=None, p=None) -> None:
        """Time ``t`` (s) and parameters ``p`` (``model.parameter_names`` order) of later calls."""
        if t is not None:
            self.direct.inputs[0][...] = self._t = float(t)
        if p is not None:
            self._p[...] = as_vector(p, self.model.np, "p")
            self._default_p = p is self.model.p0

    def _at(self, t: float, p) -> None:
        """:meth:`set`, skipped when ``t`` and the default parameters (``p`` None) are those of the last call."""
        if p is not None or not self._default_p:
            self.set(t=t, p=self.model.p0 if p is None else p)
        elif t != self._t:
            self.set(t=t)
