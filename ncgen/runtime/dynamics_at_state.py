"""Forward and inverse dynamics at one state, natural coordinates or joint space.

* :func:`forward_dynamics` — ``(q̈, λ)`` from ``M q̈ + Aᵀλ = F(t, q, q̇, u, p)``,
  ``A q̈ = γ`` (the KKT system, no stabilisation terms: on the constraint manifold the
  result is exact).  Joint accelerations: ``model.to_joint_space(q, v, a)``.
* :func:`forward_dynamics_kernel` — the same solve (:func:`ncgen.assembly.derived.kkt_function`) as one
  compiled C function (compiled once per model, cached on disk by content);
  ``forward_dynamics(..., backend="compiled")`` calls it through its door
  (:func:`forward_dynamics_door`: checks, kernel, finiteness of the result and fresh outputs or
  ``out=`` in one C call, about 1 µs beside the kernel: benchmarks/door_overhead.py).
* Joint space in and out for trees, faster: :func:`ncgen.runtime.tree_kernel.joint_forward_dynamics`
  (``nc.joint_forward_dynamics``; no multipliers, no KKT system).
* :func:`multipliers_at_samples` — ``λ`` of the KKT system at many states (a stepper run's
  output rows).
* :func:`inverse_dynamics` — the efforts ``τ`` of the actuated joints (joints with
  ``effort=``; every movable joint of a URDF) that produce the joint accelerations ``a_j``
  at ``(q_j, v_j)``: ``q̈`` from ``[A; J] q̈ = [γ; a_j − J̇ q̇]``, then ``(λ, τ)`` from
  ``Aᵀλ − B τ = F_passive − M q̈`` (``B`` the actuators' generalised-force map, ``F_passive``
  the applied force without the actuators' own efforts).  Units: N·m for rotations, N for
  translations, ``[f, τ]`` in the base frame for a free joint (Pinocchio's convention).
"""
from __future__ import annotations

import numpy as np

from ncgen.assembly.derived import joint_kkt_function, kkt_function
from ncgen.assembly.manifold import solve_linear
from ncgen.errors import ModelError
from ncgen.model.data import cached, model_data
from ncgen.model.rolling import refuse_rolling
from ncgen.runtime.tree_algorithm_kernels import rnea_applies, through
from ncgen.validation import MAX_MAGNITUDE, as_scalar, as_vector, write_out


def _kkt(model, q, v, t, u, p):
    f = model.functions
    A = np.array(f["A"](t, q, p))
    F = np.array(f["F"](t, q, v, u, p)).reshape(-1)
    gamma = np.array(f["gamma"](t, q, v, p)).reshape(-1)
    return A, F, gamma


def forward_dynamics_kernel(model, *, joint_space: bool = False, cflags=None):
    """The compiled :func:`~ncgen.assembly.derived.kkt_function` of ``model`` (``joint_space=True``:
    the :func:`~ncgen.assembly.derived.joint_kkt_function`, trees only; for ``a_j`` alone
    :func:`~ncgen.runtime.tree_kernel.joint_forward_dynamics_kernel` is several times faster)
    as a :class:`~ncgen.codegen.direct.DirectFunction`,
    built once per model (the library is cached by content).  Call ``k(t, q, v, u, p)`` →
    ``[a, lam]``, or ``k(t, qj, vj, u, p)`` → ``[aj, a, lam]`` (buffers reused by the next
    call)."""
    from ncgen.codegen.direct import compile_direct
    refuse_rolling(model, "forward_dynamics_kernel", "the accelerations with the rolling rows are rolling_system(model).accel(q, v, f) "
                   "(ncgen.assembly.nonholonomic)")

    def build():
        f = joint_kkt_function(model) if joint_space else kkt_function(model)
        return compile_direct(f"{model.name}_{'jfd' if joint_space else 'fd'}", f, cflags)

    return cached(model_data(model).forward_dynamics_kernels, joint_space, build)


class ForwardDynamicsDoor:
    """``door(q, v, u, out)``: ``(a, lam)`` of :func:`forward_dynamics_kernel` at time
    :attr:`t` and the model's parameters in one C call (:func:`~ncgen.codegen.fast_call.fast_caller`:
    lengths, kinds and magnitudes of ``q``, ``v``, ``u`` checked while copying, the kernel, its
    outputs checked finite, fresh outputs or ``out`` written); None when the result is not
    finite, a TypeError or ValueError for what it refuses (the caller's checked path names it).
    A kernel of its own (:meth:`~ncgen.codegen.direct.DirectFunction.copy`): its time and
    parameter buffers are the door's."""

    __slots__ = ("call", "kernel", "t", "zero_u")

    def __init__(self, model, call, kernel):
        self.call, self.kernel, self.t, self.zero_u = call, kernel, 0.0, np.zeros(model.nu)
        kernel.inputs[0][0] = 0.0
        kernel.inputs[-1][...] = model.p0

    def at(self, t) -> None:
        """Time ``t`` (s) of the next calls (a finite number, else the error naming ``t``)."""
        self.kernel.inputs[0][0] = self.t = as_scalar(t, "t")


def forward_dynamics_door(model):
    """The :class:`ForwardDynamicsDoor` of ``model``, made once per model (the model's
    ``data.forward_dynamics_door``), or False without the fast-call extension or when an output
    of the kernel is not dense."""
    from ncgen.codegen.fast_call import fast_caller

    data = model_data(model)
    if data.forward_dynamics_door is None:
        k = forward_dynamics_kernel(model).copy()
        f = k.function
        dense = all(f.sparsity_out(i).is_dense() and f.size2_out(i) == 1 for i in range(2))
        call = dense and fast_caller(k, 3, first=1, bound=MAX_MAGNITUDE, check="finite",
                                     outputs=[(k.outputs[0], f.size1_out(0), 0), (k.outputs[1], f.size1_out(1), 0)])
        data.forward_dynamics_door = ForwardDynamicsDoor(model, call, k) if call else False
    return data.forward_dynamics_door


def multipliers_at_samples(model, t, q, v, u, p, accel=None) -> np.ndarray:
    """``λ`` at each sample ``(t_k, q_k, v_k, u_k)`` (rows) from the KKT system (the model's
    ``accel``, as the initial multipliers of a run; ``accel``: another evaluation of it, e.g.
    the compiled one), mapped over the rows: the exact multipliers of each state, where a
    fixed-step method's own are first-order approximations (RATTLE's ``μ`` of the step ending
    there)."""
    f = model.functions["accel"] if accel is None else accel
    n = len(t)
    _, lam = f.map(n)(np.asarray(t, float)[None, :], np.asarray(q, float).T, np.asarray(v, float).T,
                      np.asarray(u, float).reshape(n, model.nu).T, np.asarray(p, float))
    return np.array(lam).reshape(model.nc, n).T


def forward_dynamics(model, q, v, u=None, p=None, t: float = 0.0, *, backend: str = "numpy", out=None):
    """``(a, lam)``: accelerations q̈ (natural coordinates) and multipliers at ``(t, q, v)``
    with inputs ``u`` (default zero) and parameters ``p`` (default ``model.p0``).
    ``backend``: ``"numpy"`` (the KKT matrix assembled and solved here) or ``"compiled"``
    (:func:`forward_dynamics_kernel` through :func:`forward_dynamics_door`, the fast path for
    repeated calls).  ``out``: a tuple of two writable C-contiguous float64 arrays of ``nq``
    and ``nc`` values, written and returned."""
    refuse_rolling(model, "forward_dynamics", "the accelerations with the rolling rows are rolling_system(model).accel(q, v, f) "
                   "(ncgen.assembly.nonholonomic)")
    if backend == "compiled" and p is None:
        try:
            door = model._data.forward_dynamics_door
        except AttributeError:              # not a model: model_data names what it is
            door = None
        if door is None:
            door = forward_dynamics_door(model)
        if door:
            if type(t) is not float or t != door.t:
                door.at(t)
            try:
                result = door.call(q, v, door.zero_u if u is None else u, out)
            except (TypeError, ValueError, OverflowError, RuntimeError):
                result = None               # the checked path below names what is wrong
            if result is not None:
                return result
    q = as_vector(q, model.nq, "q")
    v = as_vector(v, model.nq, "v")
    u = np.zeros(model.nu) if u is None else as_vector(u, model.nu, "u (model.input_names order)")
    p = model.p0 if p is None else as_vector(p, model.np, "p")
    if backend == "compiled":
        a, lam = forward_dynamics_kernel(model)(t, q, v, u, p)
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(lam))):
            raise ModelError("forward_dynamics: the KKT matrix [[M, Aᵀ], [A, 0]] is singular at this state")
        result = a.copy(), lam.copy()
        return result if out is None else write_out(out, result, "forward_dynamics")
    if backend != "numpy":
        raise ModelError(f"forward_dynamics: backend: expected 'numpy' or 'compiled', got {backend!r}")
    A, F, gamma = _kkt(model, q, v, float(t), u, p)
    nq, nc = model.nq, A.shape[0]
    K = np.block([[model.M, A.T], [A, np.zeros((nc, nc))]])
    x = solve_linear(K, np.concatenate([F, gamma]))
    if x is None:
        raise ModelError("forward_dynamics: the KKT matrix [[M, Aᵀ], [A, 0]] is singular at this state "
                         "(redundant constraints or a singular configuration; see nc.dof_report)")
    return (x[:nq], x[nq:]) if out is None else write_out(out, (x[:nq], x[nq:]), "forward_dynamics")


def _rnea_gives(model, joints: str) -> bool:
    """Whether the compiled RNEA (:func:`~ncgen.runtime.tree_algorithm_kernels.rnea`) gives the
    efforts ``joints`` asks for (a 3D tree whose asked-for efforts are those of its independent
    joint rates), decided once per model (the model's ``data.rnea_efforts``)."""
    if joints not in ("actuated", "all"):
        raise ModelError(f"inverse_dynamics: joints: expected 'actuated' or 'all', got {joints!r}")
    data = model_data(model)
    takes = data.rnea_efforts.get(joints)
    if takes is None:
        js, independent = model.joint_space, rnea_applies(model)
        sv = js.slices(rates=True)
        actuated = [i for n in js.joint_names if n in model.actuated_joints for i in range(sv[n].start, sv[n].stop)]
        takes = data.rnea_efforts[joints] = independent is not None and (
            independent == actuated if joints == "actuated" else len(independent) == js.nv)
    return takes


def inverse_dynamics(model, qj, vj, aj, p=None, t: float = 0.0, joints: str = "actuated", *,
                     out=None) -> np.ndarray:
    """Efforts of ``model.actuated_joints`` (concatenated, ``joint_names`` order) that give
    the joint accelerations ``aj`` at joint positions ``qj`` and rates ``vj`` (vectors in
    ``joint_names`` order).  ``joints="all"``: efforts conjugate to every joint rate, as if
    every joint were actuated (a floating base's wrench included; Pinocchio's ``rnea``).
    Trees (3D, mimic joints included) use the compiled RNEA
    (:func:`~ncgen.runtime.tree_algorithm_kernels.rnea`, from the tree tables when they cover the model) when the efforts asked for are those of the
    independent joint rates; other models solve the constrained equations of motion.
    ``out``: an array of the efforts' size written and returned (float64, C-contiguous)."""
    try:
        gives = model._data.rnea_efforts.get(joints)
    except AttributeError:                  # not a model: model_data names what it is
        gives = model_data(model).rnea_efforts.get(joints)
    if gives or _rnea_gives(model, joints):
        return through(model, "rnea", "auto", qj, vj, aj, p, t, out)
    t = float(t)
    js = model.joint_space
    p = model.p0 if p is None else as_vector(p, model.np, "p")
    q, v = model.from_joint_space(qj, vj, t=t, p=p)
    aj = as_vector(aj, js.nv, "aj (one value per joint rate, joint_names order)")
    f = model.functions
    A, _, gamma = _kkt(model, q, v, t, np.zeros(model.nu), p)
    J = np.array(js.jacobian(q))
    bias = np.array(js.bias(q, v)).reshape(-1)
    K = np.vstack([A, J])
    a = solve_linear(K, np.concatenate([gamma, aj - bias]))
    if a is None:
        raise ModelError("inverse_dynamics: the joint accelerations do not determine q̈ (or contradict "
                         "the constraints): give every joint's accelerations of a tree")
    B, tau0 = (np.array(x) for x in js.actuation(t, q, np.zeros(model.nu), p))
    F = np.array(f["F"](t, q, v, np.zeros(model.nu), p)).reshape(-1) - B @ tau0.reshape(-1)
    if joints == "all":
        B = J.T
    if B.shape[1] == 0:
        raise ModelError("inverse_dynamics: the model has no actuated joints (give joints effort=...)")
    rhs = F - model.M @ a
    G = np.hstack([A.T, -B])
    x = solve_linear(G, rhs)
    if x is None:
        raise ModelError(f"inverse_dynamics: these accelerations need efforts on joints without actuators "
                         f"(or the constraint forces are not unique); actuated joints: {', '.join(js.actuated)}")
    return x[A.shape[0]:] if out is None else write_out(out, x[A.shape[0]:], "inverse_dynamics")
