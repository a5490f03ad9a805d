"""nc.linearize: cart-pole against the textbook (A, B) about the upright; about a moving
state against finite differences of the vector field and of the simulated flow; the
generated C kernel against the Python evaluation."""
import shutil

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import NcgenError

M_CART, M_POLE, L_POLE, G = 1.0, 0.2, 0.5, 9.81


@pytest.fixture(scope="module")
def cartpole():
    return nc.System.from_toml("examples/cartpole.toml").build(share=False)   # coordinates named as written


def textbook_upright():
    """Linearised cart-pole, uniform pole (inertia m l²/12 about its centre), θ from the
    upright, positive towards +x, state (x, θ, ẋ, θ̇), force u on the cart."""
    m, M, lc = M_POLE, M_CART, L_POLE / 2
    J = m * L_POLE**2 / 12 + m * lc**2
    d = (M + m) * J - (m * lc) ** 2
    A = np.zeros((4, 4))
    A[0, 2] = A[1, 3] = 1
    A[2, 1] = -(m * lc) ** 2 * G / d
    A[3, 1] = (M + m) * m * G * lc / d
    B = np.array([0, 0, J / d, -m * lc / d])
    return A, B


def upright_coordinates(model):
    """G = ∂(x, θ)/∂q at the upright: x the cart's position, sin θ = (x_j − x_i)/l."""
    names = model.coordinate_names
    G = np.zeros((2, model.nq))
    G[0, names.index("cart.r_i.x")] = 1
    G[1, names.index("pole.r_j.x")] = 1 / L_POLE
    G[1, names.index("pole.r_i.x")] = -1 / L_POLE
    return G


def upright(model):
    q = model.q0.copy()
    names = model.coordinate_names
    q[names.index("pole.r_j.x")], q[names.index("pole.r_j.y")] = 0.0, L_POLE
    return nc.equilibrium(model, q, method="newton")


def test_cartpole_upright_matches_textbook(cartpole):
    eq = upright(cartpole)
    assert eq.stability == "unstable" and eq.n_negative == 1
    lin = nc.linearize(cartpole, eq, coordinates=upright_coordinates(cartpole))
    A, B = textbook_upright()
    np.testing.assert_allclose(lin.A, A, atol=1e-9)
    np.testing.assert_allclose(lin.B.reshape(-1), B, atol=1e-9)
    np.testing.assert_allclose(lin.xdot, 0, atol=1e-8)
    # the default (orthonormal) coordinates give a similar system: same eigenvalues
    lin0 = nc.linearize(cartpole, eq)
    np.testing.assert_allclose(np.sort_complex(lin0.eigenvalues), np.sort_complex(np.linalg.eigvals(A)),
                               atol=1e-6)   # a double zero eigenvalue: ~√ε
    np.testing.assert_allclose(cartpole.A(eq.q) @ lin0.N, 0, atol=1e-12)
    np.testing.assert_allclose(lin0.G @ lin0.N, np.eye(2), atol=1e-12)


def test_save(cartpole, tmp_path):
    lin = nc.linearize(cartpole, cartpole.q0)
    lin.save(tmp_path / "lin.npz")
    data = np.load(tmp_path / "lin.npz")
    np.testing.assert_array_equal(data["A"], lin.A)
    assert list(data["state_names"]) == ["z0", "z1", "w0", "w1"]


def moving_state(model):
    """The initial configuration (pole 0.3 rad off the vertical) with the cart and the
    pole moving, and a push: far from any equilibrium."""
    lin = nc.linearize(model, model.q0)
    q, v = lin.state(np.zeros(2), np.array([0.7, -1.3]))
    return q, v, np.array([2.0])


def test_moving_state_matches_vector_field_differences(cartpole):
    q, v, u = moving_state(cartpole)
    lin = nc.linearize(cartpole, q, v, u)
    assert np.abs(lin.xdot[2:]).max() > 1          # not an equilibrium

    def field(x, uu):
        qq, vv = lin.state(x[:2], x[2:])
        a, _ = cartpole.accel(qq, vv, u=uu)
        return np.concatenate([lin.G @ vv, lin.G @ a])

    eps = 1e-6
    J = np.column_stack([(field(e * eps, u) - field(-e * eps, u)) / (2 * eps) for e in np.eye(4)])
    np.testing.assert_allclose(J, lin.A, atol=1e-6)
    Bfd = (field(np.zeros(4), u + eps) - field(np.zeros(4), u - eps)) / (2 * eps)
    np.testing.assert_allclose(Bfd, lin.B.reshape(-1), atol=1e-6)
    np.testing.assert_allclose(field(np.zeros(4), u), lin.xdot, atol=1e-9)


def test_moving_state_matches_simulated_flow(cartpole):
    """Flow map x0 -> x(h) by IDAS, differentiated by central differences; its derivative is
    I + h A + O(h²): Richardson over h and h/2 leaves A + O(h²)."""
    q, v, u = moving_state(cartpole)
    lin = nc.linearize(cartpole, q, v, u)
    eps = 1e-5

    def flow_jacobian(h):
        cols = []
        for e in np.eye(4):
            ends = []
            for s in (1, -1):
                dx = s * eps * e
                q0, v0 = lin.state(dx[:2], dx[2:])
                traj = nc.simulate(cartpole, t_end=h, dt=h, q0=q0, v0=v0, u=lambda t: u,
                                   rtol=1e-12, atol=1e-14, progress=False)
                ends.append(lin.coordinates(traj.q[-1], traj.v[-1]))
            cols.append((ends[0] - ends[1]) / (2 * eps))
        return (np.column_stack(cols) - np.eye(4)) / h

    h = 4e-3
    A_flow = 2 * flow_jacobian(h / 2) - flow_jacobian(h)
    np.testing.assert_allclose(A_flow, lin.A, atol=5e-4 * np.abs(lin.A).max())


def test_inconsistent_state_is_refused(cartpole):
    q = cartpole.q0.copy()
    q[0] += 0.1
    q[1] += 0.1
    with pytest.raises(NcgenError, match="not on the constraints"):
        nc.linearize(cartpole, q + 0.05)
    with pytest.raises(NcgenError, match="velocity constraint"):
        nc.linearize(cartpole, cartpole.q0, np.ones(cartpole.nq))
    with pytest.raises(NcgenError, match="coordinates: expected a 2 × 10"):
        nc.linearize(cartpole, cartpole.q0, coordinates=np.eye(3))


@pytest.mark.skipif(shutil.which("gcc") is None and shutil.which("cc") is None, reason="C compiler needed")
def test_generated_linearization_kernel(cartpole, tmp_path):
    from ncgen.codegen import load_functions
    pkg = nc.generate(cartpole, tmp_path / "cartpole", linearization=True)
    f = load_functions(pkg, ["linearize"], backend="compiled")["linearize"]
    q, v, u = moving_state(cartpole)
    lin = nc.linearize(cartpole, q, v, u)
    A_lin, B_lin, C_lin, xdot = f(cartpole.t0, q, v, u, cartpole.p0, lin.N, lin.G)
    np.testing.assert_allclose(np.array(A_lin), lin.A, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(np.array(B_lin), lin.B, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(np.array(C_lin), lin.C, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(np.array(xdot).reshape(-1), lin.xdot, rtol=1e-10, atol=1e-10)
    header = (pkg.path / "cartpole.h").read_text()
    assert "linearize" in header


def test_spinning_top_matches_vector_field_differences():
    """3D body with a shared ground point, spinning fast (gyroscopic terms): A and B of the
    minimal model against central differences of the minimal vector field."""
    top = nc.System.from_toml("examples/heavy_top.toml").build()
    lin = nc.linearize(top, top.q0, top.v0)
    dof = lin.N.shape[1]
    assert dof == 3 and np.abs(lin.C[top.nq:, :dof]).max() > 1     # V_z matters at this speed

    def field(x):
        q, v = lin.state(x[:dof], x[dof:])
        a, _ = top.accel(q, v)
        return np.concatenate([lin.G @ v, lin.G @ a])

    eps = 1e-4          # a is quadratic in w: central differences are exact there up to round-off
    J = np.column_stack([(field(e * eps) - field(-e * eps)) / (2 * eps) for e in np.eye(2 * dof)])
    np.testing.assert_allclose(J, lin.A, atol=1e-6 * np.abs(lin.A).max())
