"""The BLAS thread rule (ncgen/blas_threads.py): inside ncgen's dense-algebra entry points every
loaded BLAS (NumPy's, SciPy's and CasADi's OpenBLAS) runs on one thread, read back from the
libraries themselves (``openblas_get_num_threads`` through threadpoolctl); outside, each is back
at the count the caller had set, also after an exception and after nested entries;
``NCGEN_BLAS_THREADS`` chooses the count or (0) leaves the BLAS alone, and a bad value is named."""
import sys

import casadi
import numpy as np
import pytest
import scipy.linalg  # noqa: F401  (SciPy's own OpenBLAS loaded, so it is among those limited)
import threadpoolctl

import ncgen as nc
from ncgen import blas_threads
from ncgen.analysis import inverse_statics as inverse_statics_module
from ncgen.analysis.tensegrity_shapes import prism
from ncgen.blas_threads import ENV, blas_limit
from ncgen.control.contact_step import ContactStepFunction
from ncgen.errors import NcgenError

OUTER = 2                   # the caller's own setting, which every exit must restore


def counts() -> dict[str, int]:
    """Each loaded BLAS's thread count, as the library reports it."""
    return {lib.filepath: lib.get_num_threads() for lib in blas_threads.blas_libraries()}


@pytest.fixture
def outer():
    """Every BLAS at OUTER threads around the test, as a user's process might have it."""
    with threadpoolctl.threadpool_limits(limits=OUTER, user_api="blas"):
        for lib in blas_threads.blas_libraries():
            lib.set_num_threads(OUTER)
        before = counts()
        assert set(before.values()) == {OUTER}, before
        yield before


def test_every_blas_is_found_casadi_s_openblas_too():
    names = " ".join(counts())
    assert "openblas" in names and blas_threads.CASADI_OPENBLAS in names, names


def test_one_thread_inside_restored_outside_after_nesting_and_an_exception(outer, monkeypatch):
    monkeypatch.delenv(ENV, raising=False)
    with blas_limit():
        assert set(counts().values()) == {1}
        with blas_limit():
            assert set(counts().values()) == {1}
        assert set(counts().values()) == {1}                # the inner exit leaves the outer limit
    assert counts() == outer
    with pytest.raises(RuntimeError, match="inside"):
        with blas_limit():
            raise RuntimeError("inside")
    assert counts() == outer


def test_the_variable_sets_the_count_or_leaves_the_blas_alone(outer, monkeypatch):
    monkeypatch.setenv(ENV, "0")
    with blas_limit():
        assert counts() == outer
    monkeypatch.setenv(ENV, "two")
    with pytest.raises(NcgenError, match=f"{ENV}: expected a whole number of threads.*'two'"):
        with blas_limit():
            pass
    assert counts() == outer


def test_an_entry_point_runs_its_algebra_on_one_thread(outer, monkeypatch):
    """nc.inverse_statics's least-norm solve sees one thread; the caller's count is back after."""
    monkeypatch.delenv(ENV, raising=False)
    seen = []
    least_norm = inverse_statics_module.least_norm

    def recording(*args):
        seen.append(counts())
        return least_norm(*args)

    monkeypatch.setattr(inverse_statics_module, "least_norm", recording)
    nodes, struts, cables = prism(3, twist=np.radians(150))
    inv = nc.inverse_statics(nodes, struts, cables, cable_min=1.0)
    assert inv.residual < 1e-9
    assert len(seen) == 1 and set(seen[0].values()) == {1}, seen
    assert counts() == outer


def test_ipopt_uses_the_openblas_that_is_limited():
    """An IPOPT solve (MUMPS) maps CasADi's OpenBLAS once: the copy the rule limits."""
    x = casadi.MX.sym("x", 2)
    solver = casadi.nlpsol("probe", "ipopt", {"x": x, "f": casadi.sumsqr(x - 1)},
                           {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes"})
    assert np.allclose(solver(x0=[0, 0])["x"], 1)
    if sys.platform != "linux":
        pytest.skip("reads /proc/self/maps")
    with open("/proc/self/maps") as maps:
        mapped = {line.split()[-1] for line in maps if blas_threads.CASADI_OPENBLAS in line}
    assert mapped == {lib for lib in counts() if blas_threads.CASADI_OPENBLAS in lib}, mapped


@pytest.mark.parametrize("entry", [
    nc.form_find, nc.inverse_statics, nc.linearize, nc.modes, nc.optimize_prestress, nc.joint_reactions,
    nc.self_stress, nc.equilibrium, nc.ilqr, nc.MPC.__call__, nc.MPC.reset,
    nc.JointMPC.__call__, ContactStepFunction.step], ids=lambda f: f.__qualname__)
def test_the_entry_points_of_dense_algebra_follow_the_rule(entry):
    assert getattr(entry, "blas_limit", False), f"{entry.__qualname__} is not decorated with one_blas_thread"
