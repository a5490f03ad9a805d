"""Every public array argument is checked for shape, kind and finiteness, with a message
naming the argument, what was expected and what was found (issue 24, class 2): strings,
complex numbers (NumPy would drop the imaginary part), booleans (read as 0 and 1), ``None``
entries (read as NaN), NaN, infinity and wrong shapes, for ``nc.simulate``, ``nc.simulate_batch``,
``nc.equilibrium``, ``nc.linearize``, the joint-space entry points, the compiled kernels
and the optimal-control conditions, bounds and warm starts."""
from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import NcgenError


@pytest.fixture(scope="module")
def pendulum():
    """A planar pendulum with one input and one parameter (nq = 4 with sharing)."""
    s = nc.System("pend", gravity=(0, -9.81))
    b = s.add_body("link", mass=1.0, inertia=0.02, position=(0.5, 0.0), coords="ruv")
    s.add_joint(nc.Revolute(s.ground, b, at=(0, 0), name="hinge", effort="tau"))
    s.add_input("tau")
    s.add_parameter("k", 1.0)
    return s.build()


def bad_values(n: int) -> dict:
    """Each kind of bad value for an argument of ``n`` numbers, and what the message must show."""
    ok = np.linspace(0.1, 0.2, n)
    with_nan, with_inf = ok.copy(), ok.copy()
    with_nan[-1], with_inf[0] = np.nan, np.inf
    return {
        "strings": (["a"] * n, r"expected .*got .*\['a'"),
        "complex": (ok + 1j, r"expected real numbers, got complex.*\(0\.1\+1j\)"),
        "None": ([None] * n, r"expected real numbers, got NoneType None at index (0|\(0, 0\))"),
        "booleans": (np.ones(n, bool), r"expected real numbers, got (booleans|bool True at index)"),
        "nan": (with_nan, r"(finite|non-finite).*nan"),
        "inf": (with_inf, r"(finite|non-finite).*inf"),
        "wrong shape": (np.ones(n + 4), rf"expected .*{n}.*{n + 4}|{n + 4}.*expected {n}"),
    }


def batch(model, **given):
    """``nc.simulate_batch`` records a run that cannot start instead of raising: its message."""
    result = nc.simulate_batch(model, 0.1, 0.05, **given)
    if result.status[0] != 0:
        raise NcgenError(str(result.message[0]))
    return result


#: a parameter vector's values are checked by name once its shape is right
P_NAME = r"p \(parameter values\)|parameter 'k'"

#: entry point -> (the argument's name (a regular expression) in the message, its size, the call with the bad value x)
ENTRIES = {
    "simulate q0": ("q0", "nq", lambda m, x: nc.simulate(m, 0.1, 0.05, q0=x, method="idas")),
    "simulate v0": ("v0", "nq", lambda m, x: nc.simulate(m, 0.1, 0.05, v0=x, method="idas")),
    "simulate u (constant)": ("u", "nu", lambda m, x: nc.simulate(m, 0.1, 0.05, u=x, method="idas")),
    "simulate u (samples)": ("u", "nu", lambda m, x: nc.simulate(m, 0.1, 0.05, method="idas",
                                                               u=np.tile(np.asarray(x, dtype=object), (3, 1)))),
    "simulate u (callable)": ("u", "nu", lambda m, x: nc.simulate(m, 0.1, 0.05, u=lambda t: x,
                                                                             method="idas")),
    "simulate p": (P_NAME, "np", lambda m, x: nc.simulate(m, 0.1, 0.05, p=x, method="idas")),
    "simulate_batch q0": ("q0", "nq", lambda m, x: batch(m, q0=x)),
    "equilibrium q_guess": ("q_guess", "nq", lambda m, x: nc.equilibrium(m, x)),
    "equilibrium u": ("u", "nu", lambda m, x: nc.equilibrium(m, u=x)),
    "equilibrium p": (P_NAME, "np", lambda m, x: nc.equilibrium(m, p=x)),
    "linearize q": ("q", "nq", lambda m, x: nc.linearize(m, x)),
    "linearize v": ("v", "nq", lambda m, x: nc.linearize(m, m.q0, x)),
    "linearize u": ("u", "nu", lambda m, x: nc.linearize(m, m.q0, u=x)),
    "linearize p": (P_NAME, "np", lambda m, x: nc.linearize(m, m.q0, p=x)),
    "to_joint_space q": ("q", "nq", lambda m, x: m.to_joint_space(x)),
    "to_joint_space v": ("v", "nq", lambda m, x: m.to_joint_space(m.q0, x)),
    "from_joint_space qj": ("qj", "nj", lambda m, x: m.from_joint_space(x)),
    "from_joint_space vj": ("vj", "nj", lambda m, x: m.from_joint_space([0.1], x)),
    "inverse_dynamics aj": ("aj", "nj", lambda m, x: nc.inverse_dynamics(m, [0.1], [0.0], x)),
    "forward_dynamics v": ("v", "nq", lambda m, x: nc.forward_dynamics(m, m.q0, x)),
    "OCP initial q": (r"initial q", "nq", lambda m, x: nc.OptimalControl(m, N=4).initial(q=x)),
    "OCP final v": ("final v", "nq", lambda m, x: nc.OptimalControl(m, N=4).final(v=x)),
    "OCP bound_input": (r"input 'tau': upper bound", "nu2",
                        lambda m, x: nc.OptimalControl(m, N=4).bound_input("tau", -1, x)),
    "OCP warm start q": ("warm_start.q", "warm", lambda m, x: nc.OptimalControl(m, N=4).solve(
        warm_start=SimpleNamespace(t=np.linspace(0, 1, 3), q=np.tile(np.asarray(x, dtype=object), (3, 1)),
                                   v=np.zeros((3, m.nq))))),
}

#: kinds that an entry point does not see as such (NaN and wrong shapes are judged elsewhere)
SKIP = {("simulate u (samples)", "wrong shape"), ("OCP bound_input", "wrong shape"),
        ("OCP bound_input", "nan"), ("OCP bound_input", "inf"), ("OCP warm start q", "wrong shape"),
        ("OCP warm start q", "strings")}


def size(model, kind: str) -> int:
    return {"nq": model.nq, "nu": model.nu, "np": model.np, "nj": 1, "nu2": 1, "warm": model.nq}[kind]


CASES = [(entry, kind) for entry in ENTRIES for kind in bad_values(1) if (entry, kind) not in SKIP]


@pytest.mark.parametrize("entry, kind", CASES, ids=[f"{e}-{k}" for e, k in CASES])
def test_array_arguments_are_checked(pendulum, entry, kind):
    name, n, call = ENTRIES[entry]
    value, found = bad_values(size(pendulum, n))[kind]
    with pytest.raises(NcgenError) as info:
        call(pendulum, value)
    message = str(info.value)
    assert re.search(name, message), message
    assert re.search(found, message), message


def test_good_arguments_still_pass(pendulum):
    """The checks refuse only what they should: ints, lists, 0-d arrays and columns pass."""
    m = pendulum
    eq = nc.equilibrium(m, list(m.q0), u=[0], p=np.array([1]))
    lin = nc.linearize(m, eq, v=[0, 0, 0, 0])
    assert lin.A.shape == (2, 2)
    traj = nc.simulate(m, 0.1, 0.05, u=0, p={"k": 2}, q0=m.q0.tolist(), method="idas")
    assert traj.q.shape == (3, m.nq)
    # the joint-space form agrees with the natural one (an independent path: the hinge angle)
    qj = m.to_joint_space(traj.q[-1])
    s, c = m.coordinate("link.r_i.y")
    assert s @ traj.q[-1] + c == pytest.approx(0.5 * np.sin(float(np.ravel(qj)[0])), abs=1e-9)
