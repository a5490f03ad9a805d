"""Kinematics: assembly from perturbed configurations, velocity projection, DOF and
redundancy reports, driven mechanisms against the analytic slider-crank."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import ncgen as nc

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def _load(name: str):
    return nc.System.from_toml(EXAMPLES / f"{name}.toml").build()


@pytest.mark.parametrize("name", ["fourbar_planar", "fourbar_3d"])
def test_fourbar_assembles_from_a_perturbed_configuration(name):
    model = _load(name)
    report = nc.dof_report(model)
    assert (report.dof, report.redundant) == (1, [])
    rng = np.random.default_rng(5)
    q = model.q0 + 0.05 * rng.normal(size=model.nq)
    assert np.abs(model.phi(q)).max() > 1e-3
    fixed = "crank.r_j.x"
    k = model.coordinate_names.index(fixed)
    qa = nc.assemble(model, q, fix=[fixed])
    assert np.abs(model.phi(qa)).max() < 1e-12
    assert qa[k] == q[k]
    assert np.linalg.norm(qa - q) < 0.5
    assert nc.dof_report(model, qa).dof == 1
    qb = nc.assemble(model, q)
    assert np.abs(model.phi(qb)).max() < 1e-12


def test_assembly_failure_names_the_constraint():
    model = _load("fourbar_planar")
    q = model.q0.copy()
    # 4 coordinates: the crank's pivot is a ground point (coordinate sharing), its tip is coupler.r_i
    with pytest.raises(nc.ModelError, match=r"assembly failed with 4 coordinate\(s\) fixed: .* still has the residual"):
        nc.assemble(model, q + 0.1, fix=["crank", "coupler.r_j"])


def test_project_velocity_keeps_fixed_components():
    model = _load("fourbar_3d")
    rng = np.random.default_rng(0)
    v = rng.normal(size=model.nq)
    w = nc.project_velocity(model, model.q0, v)
    assert np.abs(model.A(model.q0) @ w).max() < 1e-12
    # the smallest change in kinetic-energy norm: w - v is M-orthogonal to the null space of A
    k = model.coordinate_names.index("crank.r_j.y")
    wf = nc.project_velocity(model, model.q0, v, fix=["crank.r_j.y"])
    assert wf[k] == v[k] and np.abs(model.A(model.q0) @ wf).max() < 1e-10
    N = np.linalg.svd(model.A(model.q0))[2][model.nq - 1:].T
    assert np.abs(N.T @ model.M @ (w - v)).max() < 1e-10


def _fourbar_3d_four_revolutes():
    """The classic overconstrained linkage: three bodies and four parallel revolutes."""
    s = nc.System("fourbar_4r")
    z = (0, 0, 1)

    def link(name, a, b):
        a, b = np.asarray(a, float), np.asarray(b, float)
        e = (b - a) / np.linalg.norm(b - a)
        R = np.column_stack([e, np.cross(z, e), z])
        return s.add_body(name, mass=1.0, inertia=np.diag([0.01, 0.1, 0.1]), position=(a + b) / 2, rotation=R)

    O, B, C, D = (0, 0, 0), (0.5, 0.8660254037844386, 0), (3.0428529212959905, 2.4578479506333157, 0), (3.5, 0, 0)
    crank, coupler, rocker = link("crank", O, B), link("coupler", B, C), link("rocker", C, D)
    for name, A_, B_, at in (("O", s.ground, crank, O), ("B", crank, coupler, B), ("C", coupler, rocker, C),
                             ("D", rocker, s.ground, D)):
        s.add_joint(nc.Revolute(A_, B_, at=at, axis=z, name=name))
    return s


def test_fourbar_with_four_revolutes_has_three_redundant_constraints():
    s = _fourbar_3d_four_revolutes()
    with pytest.raises(nc.ModelError, match=r"redundant constraints at the initial configuration: D\.coincide\.z, "
                                            r"D\.align\.1, D\.align\.2"):
        s.build(redundant="error", share=False)
    with pytest.warns(UserWarning, match="dropping redundant constraints D.coincide.z, D.align.1, D.align.2"):
        model = s.build(share=False)
    report = nc.dof_report(model)
    assert model.dof == report.dof == 1
    assert report.dropped == ["D.coincide.z", "D.align.1", "D.align.2"] and report.dependent == []
    assert "redundant constraints: D.coincide.z, D.align.1, D.align.2" in str(report)


def test_dof_report_names_dependent_constraints_that_were_kept():
    model = _fourbar_3d_four_revolutes().build(redundant="keep", share=False)
    report = nc.dof_report(model)
    assert report.dependent == ["D.coincide.z", "D.align.1", "D.align.2"] and report.dropped == []
    assert (report.nq, report.nc, report.rank, report.dof) == (36, 38, 35, 1)


def _slider_crank(drive="omega*t"):
    """Crank r = 0.5 from 45°, driven; coupler l = 1.5; slider on the x axis."""
    s = nc.System("slider_crank", gravity=(0, -9.81))
    s.add_parameter("omega", 2 * np.pi)
    crank = s.add_bar("crank", mass=0.3, ends=[(0, 0), 0.5 * np.array([np.cos(np.pi / 4), np.sin(np.pi / 4)])])
    x0 = 0.5 * np.cos(np.pi / 4) + np.sqrt(1.5**2 - (0.5 * np.sin(np.pi / 4)) ** 2)
    slider = s.add_body("slider", coords="ruv", mass=1.0, inertia=0.01, position=(x0, 0))
    s.add_bar("coupler", mass=0.6, ends=[crank.end(1), slider.node("r_i")])
    s.add_joint(nc.Revolute(s.ground, crank, at=(0, 0), drive=drive))
    s.add_joint(nc.Prismatic(s.ground, slider, at=(x0, 0), axis=(1, 0)))
    return s


def test_slider_crank_kinematics_matches_the_analytic_formula():
    model = _slider_crank().build()
    assert nc.dof_report(model).dof == 0
    times = np.linspace(0, 1, 41)
    sol = nc.solve_kinematics(model, times)
    r, l, w = 0.5, 1.5, 2 * np.pi
    th = np.pi / 4 + w * times
    root = np.sqrt(l**2 - (r * np.sin(th)) ** 2)
    x = r * np.cos(th) + root
    xd = -r * w * np.sin(th) - r**2 * w * np.sin(th) * np.cos(th) / root
    xdd_fd = np.gradient(xd, times, edge_order=2)
    k = model.coordinate_names.index("slider.r_i.x")
    assert np.allclose(sol.q[:, k], x, atol=1e-10)
    assert np.allclose(sol.v[:, k], xd, atol=1e-9)
    xdd = -r * w**2 * np.cos(th) - r**2 * w**2 * np.cos(2 * th) / root \
        - r**4 * w**2 * np.sin(th) ** 2 * np.cos(th) ** 2 / root**3
    assert np.allclose(sol.a[:, k], xdd, atol=1e-8)
    assert np.allclose(xdd[1:-1], xdd_fd[1:-1], atol=0.5)          # the formula itself, roughly
    assert sol.residual < 1e-12


def test_solve_kinematics_refuses_a_mechanism_with_free_dof():
    model = _load("fourbar_planar")
    with pytest.raises(nc.ModelError, match=r"the mechanism has 1 degree\(s\) of freedom"):
        nc.solve_kinematics(model, [0.0, 0.1])


def test_build_assemble_keeps_the_fixed_member():
    """Joints given at world points hold in the given configuration by construction; a
    coordinate driver that prescribes another position needs assembling."""
    s = nc.System("double", gravity=(0, -9.81))
    b1 = s.add_bar("b1", mass=1.0, ends=[s.ground.point((0, 0)), (1, 0)])
    b2 = s.add_bar("b2", mass=1.0, ends=[b1.end(1), (1.6, 0.8)])
    s.add_joint(nc.CoordinateDriver(b2, "r_j", "x", 1.5))
    with pytest.raises(nc.ModelError, match=r"inconsistent initial configuration: the constraints are violated "
                                            r"\(coordinatedriver_0.coordinate = 0.1\); .* build\(assemble=True\)"):
        s.build()
    model = s.build(assemble=True, fix=["b1"])
    i1, i2 = model.layout.member_indices("b1"), model.layout.member_indices("b2")
    assert np.array_equal(model.q0[[i for i in i1 if i is not None]], [1.0, 0.0])
    assert np.allclose(model.q0[i2[2:]], [1.5, np.sqrt(0.75)])
    assert np.abs(model.phi(model.q0)).max() < 1e-12
    assert np.isclose(model.initial_residual[0], 0.1) and model.initial_correction[0] > 0.05
    free = s.build(assemble=True).q0                       # minimum-norm: both bars move
    assert not np.allclose(free[model.layout.member_indices("b1")[2:]], [1.0, 0.0])


def test_build_assemble_moves_to_the_driven_position():
    s = _slider_crank("0.5 + omega*t")
    with pytest.raises(nc.ModelError, match="inconsistent initial configuration"):
        s.build()
    model = s.build(assemble=True)
    k = model.coordinate_names.index("slider.r_i.x")
    th = np.pi / 4 + 0.5
    assert np.isclose(model.q0[k], 0.5 * np.cos(th) + np.sqrt(1.5**2 - (0.5 * np.sin(th)) ** 2))


def test_fix_names_are_checked():
    model = _load("fourbar_planar")
    with pytest.raises(nc.ModelError, match=r"fix: no coordinate, slot or member named 'crnk' \(did you mean 'crank'\?\)"):
        nc.assemble(model, fix=["crnk"])
    with pytest.raises(nc.ModelError, match=r"fix: crank \(rr\) has slots r_i, r_j, got 'u'"):
        nc.assemble(model, fix=["crank.u"])


def test_sparse_matrices_keep_their_entries_in_place():
    """``sparse_dm`` of a non-symmetric matrix is that matrix (its nonzeros once went in row
    order into CasADi's column-ordered storage, which scrambled A in the velocity projection)."""
    from ncgen.assembly.mass import sparse_dm

    rng = np.random.default_rng(3)
    B = rng.normal(size=(5, 7)) * (rng.random((5, 7)) < 0.4)
    np.testing.assert_array_equal(np.array(sparse_dm(B).full()), B)


@pytest.mark.parametrize("shape", [(5, 7), (7, 5), (0, 4), (4, 0), (1, 1)])
def test_dense_and_sparse_forms_are_each_others_inverse(shape):
    """``dense_dm`` (a CasADi matrix scattered from its nonzeros) gives the entries NumPy's own
    conversion gives, bit for bit (a ``-0.0`` nonzero kept), and ``sparse_dm`` keeps exactly
    the nonzero entries of a non-contiguous array."""
    import casadi as ca

    from ncgen.assembly.mass import dense_dm, sparse_dm

    rng = np.random.default_rng(5)
    B = rng.normal(size=shape) * (rng.random(shape) < 0.4)
    X = ca.DM(ca.Sparsity.dense(*shape), B.ravel(order="F"))
    if B.size:
        X[0, 0] = -0.0
    D = dense_dm(X)
    assert D.shape == shape and np.array_equal(D.view(np.uint64), np.array(X).view(np.uint64))
    T = np.asfortranarray(B.T)[:, ::-1]                 # neither C-ordered nor contiguous
    S = sparse_dm(T)
    assert S.nnz() == np.count_nonzero(T) and np.array_equal(dense_dm(S), T)


def test_velocity_projection_is_the_kinetic_energy_nearest_solution():
    """At the slider-crank's dead centre with the motor at ω, the projection of v = 0 is the
    unique velocity of the driven mechanism: crank tip ω r upwards, slider at rest."""
    from ncgen.assembly.manifold import project

    model = _load("slider_crank")
    omega = float(model.p0[0])
    names = model.coordinate_names
    assert model.v0[names.index("crank.r_j.y")] == pytest.approx(omega * 0.1, rel=1e-12)
    assert abs(model.v0[names.index("slider.r_i.x")]) < 1e-12
    rng = np.random.default_rng(11)
    A = rng.normal(size=(3, 6))
    M = np.diag(rng.uniform(0.5, 2.0, size=6))
    v, b = rng.normal(size=6), rng.normal(size=3)
    w = project(A, b, v, M, range(6))
    Mi = np.linalg.inv(M)
    expected = v + Mi @ A.T @ np.linalg.solve(A @ Mi @ A.T, b - A @ v)
    np.testing.assert_allclose(w, expected, rtol=1e-10, atol=1e-12)
