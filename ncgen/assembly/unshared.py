"""The unshared form of a model whose joints coordinate sharing eliminated, and the linear
map between the two coordinate vectors (used for the reactions of eliminated joints).

Coordinate sharing (:mod:`ncgen.model.sharing`) re-bases bodies and merges nodes but keeps
every member's frame and motion, so the natural coordinates of the same system built with
``share=False`` are an affine function of the shared ones:

    q_u = S q_s + c,    v_u = S v_s,    a_u = S a_s.

Per member, each basic point of its unshared coordinate type is a body-fixed point,
``r = C_s(c(r̄)) q_I``, and each base vector a body-fixed direction,
``u = (C_s(c(ū)) − C_s(c(0))) q_I`` (``C_s`` of the shared type, ``r̄``, ``ū`` in the member's
frame); bars and point members keep their coordinates (``S`` is the identity on them).
Sharing nodes makes ``q_I = P_I q_s + b_I`` (:mod:`ncgen.model.layout`).  The unshared model
is built on first use (about the cost of the shared build: 0.2–0.3 s for a 7-joint arm).
"""
from __future__ import annotations

import warnings

import numpy as np

from ncgen.errors import ModelError, NcgenError
from ncgen.model.data import model_data


class UnsharedForm:
    """How to build the ``share=False`` form of a shared model: the system as written
    (``source``), the build options and ``builder`` (:func:`ncgen.assembly.build.build_model`).
    Constant; the built model and the map ``(S, c)``
    from the shared coordinates to its coordinates are kept in the shared model's data
    (``model.data.unshared_model``, ``model.data.unshared_map``)."""

    def __init__(self, source, options: dict, builder):
        self.source = source
        self.options = dict(options)
        self.builder = builder

    def build(self):
        """The ``share=False`` model of the same system (same build options), without the
        system's initial coordinates (``System.initial_coordinates``: the shared build sets
        them through this model's map, which does not depend on the state)."""
        source = object.__new__(type(self.source))            # a shallow copy (not through pickling)
        source.__dict__.update(self.source.__dict__)
        source.initial_coordinates, source.initial_coordinate_rates = {}, {}
        return self.builder(source, share=False, **self.options)

    def model(self, shared):
        """The ``share=False`` model of ``shared`` (built on first use)."""
        data = model_data(shared)
        if data.unshared_model is None:
            try:
                with warnings.catch_warnings():      # the shared build already reported on the system
                    warnings.simplefilter("ignore")
                    data.unshared_model = self.build()
            except NcgenError as e:
                raise ModelError(f"the reactions of joints eliminated by coordinate sharing need the model "
                                 f"built with share=False, which failed: {e}") from None
        return data.unshared_model

    def coordinate_map(self, shared) -> tuple[np.ndarray, np.ndarray]:
        """``(S, c)`` with ``q_u = S q_s + c`` (``S``: unshared nq × shared nq)."""
        data = model_data(shared)
        if data.unshared_map is None:
            data.unshared_map = coordinate_map(shared, self.model(shared))
        return data.unshared_map


def member_map(shared_member, unshared_member) -> np.ndarray:
    """``T`` with ``q_I,u = T q_I,s``: one member's unshared coordinates from its shared ones."""
    ms, mu = shared_member, unshared_member
    if ms.kind != "body":
        if ms.ctype.name != mu.ctype.name:
            raise ModelError(f"{ms.name}: coordinate sharing changed a {ms.kind}'s coordinates "
                             f"({mu.ctype.name} -> {ms.ctype.name}); only bodies are re-based")
        return np.eye(ms.ctype.nq)
    rigid, d = ms.rigid, ms.dim
    C0 = rigid.C(rigid.affine(np.zeros(d)))
    rows = []
    for s in range(len(mu.ctype.slots)):
        world = mu.slot_position(s)
        if s in mu.ctype.point_slots:
            rows.append(rigid.C(rigid.affine(mu.to_local(world))))
        else:
            rows.append(rigid.C(rigid.affine(mu.direction_to_local(world))) - C0)
    return np.vstack(rows)


def coordinate_map(shared, unshared) -> tuple[np.ndarray, np.ndarray]:
    """``(S, c)`` with ``q_u = S q_s + c`` between two models of the same members (see the
    module docstring); checked at the initial configuration."""
    S = np.zeros((unshared.nq, shared.nq))
    c = np.zeros(unshared.nq)
    done = np.zeros(unshared.nq, bool)
    for name in unshared.member_names:
        T = member_map(shared.members[name], unshared.members[name])
        cols = shared.layout.member_indices(name)
        P = np.zeros((len(cols), shared.nq))
        for k, i in enumerate(cols):
            if i is not None:
                P[k, i] = 1.0
        TP, Tb = T @ P, T @ shared.layout.member_constant(name)
        for k, i in enumerate(unshared.layout.member_indices(name)):
            if i is not None and not done[i]:
                S[i], c[i], done[i] = TP[k], Tb[k], True
    if not done.all():
        raise ModelError(f"model {shared.name!r}: the unshared coordinates "
                         f"{', '.join(unshared.coordinate_names[i] for i in np.flatnonzero(~done))} "
                         "belong to no member")
    q_u = S @ shared.q0 + c
    err = float(np.max(np.abs(unshared.phi(q_u, t=shared.t0)), initial=0.0))
    scale = max(1.0, float(np.max(np.abs(q_u), initial=0.0)))
    if err > 1e-8 * scale**2:
        raise ModelError(f"model {shared.name!r}: the shared coordinates do not map onto the unshared "
                         f"model's constraints (|Φ| = {err:.3g} at the initial configuration)")
    return S, c
