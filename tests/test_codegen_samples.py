"""Sample CasADi functions for the codegen tests (imported by the other test_codegen_* files).

A planar chain of three point masses joined by rigid links of lengths ``l`` (a parameter),
first point linked to the origin, with a nonlinear spring-damper force: small, but with
sparse Jacobians, trigonometry, square roots and constant sparse outputs.
"""
import casadi as ca
import numpy as np

from ncgen.codegen import PackageDoc

NQ = 6


def chain_functions() -> list[ca.Function]:
    q, v = ca.SX.sym("q", NQ), ca.SX.sym("v", NQ)
    l, k = ca.SX.sym("l", 3), ca.SX.sym("k", 1)
    pts = [ca.SX.zeros(2)] + [q[2 * i:2 * i + 2] for i in range(3)]
    phi = ca.vertcat(*[ca.sumsqr(pts[i + 1] - pts[i]) - l[i] ** 2 for i in range(3)])
    A = ca.jacobian(phi, q)
    gamma = -ca.mtimes(ca.jacobian(ca.mtimes(A, v), q), v)
    stretch = ca.sqrt(ca.sumsqr(q[4:6]) + 1e-3) - ca.sum1(l)
    force = ca.vertcat(ca.SX.zeros(3), -9.81, k * stretch * ca.sin(q[4]), -k * stretch * ca.cos(q[5]) - 0.1 * v[5])
    M = ca.SX(ca.DM(ca.Sparsity.diag(NQ), [1.0, 1.0, 2.0, 2.0, 0.5, 0.5]))
    return [
        ca.Function("phi", [q, l], [phi, A], ["q", "l"], ["phi", "A"]),
        ca.Function("gamma", [q, v, l], [gamma], ["q", "v", "l"], ["gamma"]),
        ca.Function("force", [q, v, l, k], [force, ca.jacobian(force, q), ca.jacobian(force, v)],
                    ["q", "v", "l", "k"], ["F", "F_q", "F_v"]),
        ca.Function("mass", [], [M], [], ["M"]),
    ]


def chain_doc() -> PackageDoc:
    return PackageDoc(
        summary="Planar chain of three point masses (codegen test sample).",
        functions={
            "phi": {"purpose": "Constraints and their Jacobian",
                    "inputs": {"q": ("coordinates", "m"), "l": ("link lengths", "m")},
                    "outputs": {"phi": ("constraint residuals", "m^2"), "A": ("Jacobian dphi/dq", "m")}},
            "gamma": "Constraint acceleration right-hand side",
            "force": {"purpose": "Generalized forces and their Jacobians",
                      "outputs": {"F": {"meaning": "generalized force", "units": "N"}}},
            "mass": "Constant mass matrix",
        },
        metadata={"nq": NQ, "nc": 3, "q0": [1.0, 0.0, 2.0, 0.0, 3.0, 0.0], "v0": np.zeros(NQ),
                  "l0": [1.0, 1.0, 1.0], "k0": [100.0], "q_names": [f"{c}{i}" for i in (1, 2, 3) for c in "xy"],
                  "gravity": -9.81, "model": "chain3"},
        metadata_doc={"nq": "number of coordinates", "q0": "default initial coordinates [m]"},
        defaults={"q": "q0", "v": "v0", "l": "l0", "k": "k0"},
        main_function="force",
    )


def random_inputs(f: ca.Function, rng: np.random.Generator) -> list[np.ndarray]:
    return [rng.standard_normal(f.size_in(i)) for i in range(f.n_in())]


def test_samples_have_sparse_jacobians():
    phi, _, force, mass = chain_functions()
    assert 0 < phi.sparsity_out("A").nnz() < phi.numel_out("A")
    assert 0 < force.sparsity_out("F_q").nnz() < force.numel_out("F_q")
    assert mass.sparsity_out(0).nnz() == NQ
