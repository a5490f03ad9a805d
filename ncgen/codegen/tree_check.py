"""What every compiled kernel of a tree shares: the algorithms' signatures, the check that a
model is a tree (mimic joints allowed), the accepted Cholesky pivot, the compile flags of long
kernels and the normalisation of joint quaternions."""
from __future__ import annotations

import numpy as np

from ncgen.errors import ModelError

#: ``name: (inputs after t before p, outputs)`` of every algorithm.
ALGORITHMS = {
    "rnea": (("qj", "vj", "aj"), ("tau",)),
    "crba": (("qj",), ("M",)),
    "aba": (("qj", "vj", "tau"), ("aj",)),
    "rnea_derivatives": (("qj", "vj", "aj"), ("tau", "dtau_dq", "dtau_dv", "dtau_da")),
    "aba_derivatives": (("qj", "vj", "tau"), ("aj", "da_dq", "da_dv", "da_dtau")),
}


#: Smallest accepted relative Cholesky pivot of the joint-space mass matrix ``M_j``
#: (``d_k / (M_j)_kk ≥ 1 / cond``): below it the dynamics are refused as singular.
PIVOT_TOL = 1e-12
#: Kernels longer than the package's LARGE_FUNCTION_INSTRUCTIONS (compiled at -O0 by default)
#: but at most this long are compiled at -O1: the Talos humanoid's (38 joint rates, 29 k
#: instructions) compiles in 4.2–4.5 s at -O1 and runs in 9–17 µs, against 50 µs at -O0; gcc's
#: -O1 time grows faster than linearly (a 40-hinge chain, 55 k instructions: 20 s).
O1_INSTRUCTIONS = 40_000
#: The tree map holds every constraint to this (relative; m² for Φ): a loop or a drive misses
#: by about the random step (0.1 rad), rounding through a long chain of URDF frames by 1e-13.
TREE_TOL = 1e-9


def check_tree(model) -> None:
    """Raise :class:`ModelError` unless ``model`` is a tree: its members hang from the ground
    through joints with coordinates (and Fixed joints), with no other constraints than mimic
    joints (:class:`~ncgen.assembly.tree_dynamics.MimicMap`).  Checked at a random state: the
    tree map satisfies every constraint and the model has exactly as many degrees of freedom
    as independent joint rates."""
    from ncgen.assembly.manifold import numerical_rank
    from ncgen.assembly.tree_dynamics import MimicMap

    js = model.joint_space
    js.spanning_tree()
    if js.nv == 0:
        raise ModelError("joint forward dynamics: the model has no joints with coordinates")
    mimic = MimicMap(model)
    if mimic.relations and js.dim != 3:
        raise ModelError("joint forward dynamics: mimic joints are taken by the recursive form only (3D models)")
    rng = np.random.default_rng(1)
    qj = np.array(js.positions(model.q0)).reshape(-1) + 0.1 * rng.standard_normal(js.nq)
    for name, s in js.slices().items():
        if js.dim == 3 and js.nq_joint[name] in (4, 7):
            qj[s.stop - 4:s.stop] /= np.linalg.norm(qj[s.stop - 4:s.stop])
    for i, (lead, k, offset) in mimic.position.items():
        qj[i] = k * qj[lead] + offset
    vj = mimic.G @ rng.standard_normal(mimic.G.shape[1])
    q, v = (np.array(x).reshape(-1) for x in tree_function(model)(qj, vj))
    f = model.functions
    A = np.array(f["A"](model.t0, q, model.p0))
    size = max(1.0, float(np.max(np.abs(q), initial=0.0)))
    phi = np.array(f["phi"](model.t0, q, model.p0)).reshape(-1)
    rate = A @ v + np.array(f["phi_t"](model.t0, q, model.p0)).reshape(-1)
    if np.max(np.abs(phi), initial=0.0) > TREE_TOL * size**2 or \
            np.max(np.abs(rate), initial=0.0) > TREE_TOL * size * max(1.0, float(np.max(np.abs(v)))):
        raise ModelError("joint forward dynamics: the model has constraints besides its tree of joints "
                         "and mimic joints (drives or loop-closing joints)")
    dof = model.nq - numerical_rank(A)
    if dof != mimic.G.shape[1]:
        raise ModelError(f"joint forward dynamics: the model has {dof} degrees of freedom but "
                         f"{mimic.G.shape[1]} independent joint rates")


def tree_function(model):
    """The tree map ``(qj, vj) -> (q, v)`` of ``model``
    (:meth:`~ncgen.assembly.joint_space.JointSpace.tree_function`), derived once per process and
    kept in ``model.data``; for a model read from the store of built models, read from the store
    (deriving it takes the coordinate types' SymPy derivations, seconds for a URDF robot)."""
    from ncgen.codegen.model_cache import derived_function
    from ncgen.model.data import model_data

    data = model_data(model)
    if data.joint_tree_function is None or data.joint_tree_function[0] is None:
        f = derived_function(model, "joint-tree", lambda: model.joint_space.tree_function(model.layout))
        data.joint_tree_function = (f,)
    return data.joint_tree_function[0]


def compile_tree_function(model, f, cflags, suffix: str):
    """``f`` compiled alone as the package ``<model>_<suffix>`` and loaded for direct calls
    (:func:`~ncgen.codegen.direct.compile_direct`; default flags as in the module docstring)."""
    import os

    from ncgen.codegen.direct import compile_direct
    from ncgen.codegen.package import LARGE_FUNCTION_INSTRUCTIONS

    if cflags is None and "NCGEN_CFLAGS" not in os.environ and \
            LARGE_FUNCTION_INSTRUCTIONS < f.n_instructions() <= O1_INSTRUCTIONS:
        cflags = "-O1"
    return compile_direct(f"{model.name}_{suffix}", f, cflags)


def quaternion_offsets(js) -> list[int]:
    """Where the quaternion ``[qx, qy, qz, qw]`` of each spherical and free joint starts in
    ``qj`` (the entries :func:`unit_quaternions` normalises; none in 2D)."""
    if js.dim != 3:
        return []
    return [s.stop - 4 for name, s in js.slices().items() if js.nq_joint[name] in (4, 7)]


def unit_quaternions(js, qj: np.ndarray) -> np.ndarray:
    """``qj`` (one state, or one per row) with the quaternions of spherical and free joints
    normalised (qw ≥ 0)."""
    if js.dim != 3:
        return qj
    qj = qj.copy()
    for name, s in js.slices().items():
        if js.nq_joint[name] in (4, 7):
            x = qj[..., s.stop - 4:s.stop]
            n = np.linalg.norm(x, axis=-1, keepdims=True)
            if not np.all(n > 0):
                row = "" if qj.ndim == 1 else f" in row {int(np.argmin(n.reshape(-1) > 0))}"
                raise ModelError(f"qj[{name!r}]: the quaternion [qx, qy, qz, qw] is zero{row}")
            qj[..., s.stop - 4:s.stop] = x / n * np.where(x[..., 3:] >= 0, 1.0, -1.0)
    return qj


