"""``Model``: a built system — dimensions, names, consistent initial state, the constant mass
matrix and the whole-system CasADi functions (see :mod:`ncgen.assembly.functions`).

Numeric conveniences (``model.phi(q)``, ``model.A(q)``, ...) evaluate those functions with
the default parameters and zero inputs unless told otherwise and return NumPy arrays.
"""
from __future__ import annotations

import numpy as np

from ncgen.validation import as_vector


class Model:
    """A validated, assembled system (create it with ``System.build()``)."""

    def __init__(self, *, system, layout, labels, functions, M, factor, potential, state, p0, baumgarte,
                 redundant, dropped, t0, sharing=None):
        self.system = system
        self.name = system.name
        self.dim = system.dim
        self.layout = layout
        self.functions = functions
        self.M = M
        self.mass_factor = factor
        self.potential_terms = potential
        self.constraint_names = list(labels)
        self.coordinate_names = layout.coordinate_names
        self.input_names = list(system.inputs)
        self.input_sizes = [int(s.shape[0]) for s in system.inputs.values()]
        self.parameter_names = list(system.parameters)
        self.parameter_sizes = [int(v.size) for _, v in system.parameters.values()]
        self.member_names = list(system.members)
        self.marker_names = [f"{m.name}.{k}" for m in system.members.values() for k in m.markers]
        self.p0 = np.asarray(p0, dtype=float)
        self.q0, self.v0 = state.q0, state.v0
        self.lam0, self.a0 = state.lam0, state.a0
        self.initial_correction = (state.dq, state.dv)
        self.initial_residual = (state.phi_given, state.velocity_given)
        self.baumgarte = baumgarte
        self.redundant = list(redundant)
        self.redundant_dropped = dropped and bool(redundant)
        self.t0 = t0
        self.gravity = system.gravity.copy()
        #: :class:`~ncgen.model.sharing.SharingPlan` of ``build(share=True)`` (None with share=False).
        self.sharing = sharing

    # ------------------------------------------------------------ dimensions
    @property
    def nq(self) -> int:
        return self.layout.nq

    @property
    def nc(self) -> int:
        return len(self.constraint_names)

    @property
    def nu(self) -> int:
        return int(sum(self.input_sizes))

    @property
    def np(self) -> int:
        return int(self.p0.size)

    @property
    def rank(self) -> int:
        """Rank of A at the initial configuration."""
        A = self.A(self.q0)
        return int(np.linalg.matrix_rank(A)) if A.size else 0

    @property
    def dof(self) -> int:
        """Degrees of freedom: nq − rank A(q0)."""
        return self.nq - self.rank

    @property
    def Minv(self) -> np.ndarray:
        """Dense M⁻¹ (constant; for small models and checks)."""
        return self.mass_factor.solve_numeric(np.eye(self.nq))

    # ------------------------------------------------------------- numerics
    def _args(self, q=None, v=None, t=None, u=None, p=None):
        out = {}
        if q is not None:
            out["q"] = as_vector(q, self.nq, "q")
        if v is not None:
            out["v"] = as_vector(v, self.nq, "v")
        out["t"] = self.t0 if t is None else float(t)
        out["u"] = np.zeros(self.nu) if u is None else as_vector(u, self.nu, "u")
        out["p"] = self.p0 if p is None else as_vector(p, self.np, "p")
        return out

    def _call(self, name, **kw):
        f = self.functions[name]
        a = self._args(**kw)
        res = f.call({k: a[k] for k in f.name_in()})
        outs = [np.array(res[k]) for k in f.name_out()]
        outs = [o.reshape(-1) if o.ndim == 2 and o.shape[1] == 1 else o for o in outs]
        return outs[0] if len(outs) == 1 else tuple(outs)

    def phi(self, q, t=None, p=None) -> np.ndarray:
        return self._call("phi", q=q, t=t, p=p)

    def A(self, q, t=None, p=None) -> np.ndarray:
        return self._call("A", q=q, t=t, p=p)

    def gamma(self, q, v, t=None, p=None) -> np.ndarray:
        return self._call("gamma", q=q, v=v, t=t, p=p)

    def F(self, q, v, t=None, u=None, p=None) -> np.ndarray:
        return self._call("F", q=q, v=v, t=t, u=u, p=p)

    def accel(self, q, v, t=None, u=None, p=None):
        """``(a, λ)`` from the KKT system (Baumgarte terms included)."""
        return self._call("accel", q=q, v=v, t=t, u=u, p=p)

    def energy(self, q, v, t=None, p=None):
        """``(T, V)``: kinetic and potential energy (J)."""
        T, V = self._call("energy", q=q, v=v, t=t, p=p)
        return float(np.asarray(T).item()), float(np.asarray(V).item())

    def markers(self, q, v=None):
        """World positions (and velocities) of the named markers, ``dim × n_markers``."""
        v = np.zeros(self.nq) if v is None else v
        return self._call("markers", q=q, v=v)

    def poses(self, q):
        """``(R, p)`` of every member: ``R`` is ``n × dim × dim``, ``p`` is ``n × dim``."""
        R, p = self._call("poses", q=q)
        n, d = len(self.member_names), self.dim
        R = np.asarray(R).reshape(d, n, d).transpose(1, 0, 2) if n else np.zeros((0, d, d))
        return R, np.asarray(p).reshape(d, n).T

    def parameters(self, **values) -> np.ndarray:
        """The parameter vector with some entries replaced by name: ``model.parameters(k=50)``."""
        p = self.p0.copy()
        offsets = np.cumsum([0] + self.parameter_sizes)
        for name, val in values.items():
            if name not in self.parameter_names:
                raise KeyError(f"unknown parameter {name!r}; parameters: {', '.join(self.parameter_names)}")
            i = self.parameter_names.index(name)
            p[offsets[i]:offsets[i + 1]] = np.atleast_1d(np.asarray(val, float)).reshape(-1)
        return p

    def member(self, name: str):
        return self.system.member(name)

    def __repr__(self) -> str:
        return (f"<Model {self.name!r}: dim={self.dim}, nq={self.nq}, nc={self.nc}, dof={self.dof}, "
                f"nu={self.nu}, np={self.np}>")
