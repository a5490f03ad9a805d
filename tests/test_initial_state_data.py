"""The initial state is the package's data, not its code (issue 34: a second model of
shipped kinds reaches compiled code with nothing compiled): the same system at a new
initial state reuses the compiled library of the first, and its run starts at its own q0."""
import math

import numpy as np
import pytest

import ncgen as nc
import ncgen.codegen.compile_cache as compile_cache
from ncgen.codegen.model_package import SYSTEM_FUNCTIONS

L, G = 1.0, 9.81


def pendulum(theta: float) -> nc.System:
    """A planar bar pendulum of length L (m) hinged at the origin, at angle ``theta`` (rad)
    from the downward vertical: only the initial state depends on ``theta``."""
    s = nc.System("swing", gravity=(0.0, -G))
    s.add_bar("bar", coords="rr", mass=1.0, ends=[s.ground.point((0.0, 0.0)),
                                                   (L * math.sin(theta), -L * math.cos(theta))])
    return s


@pytest.fixture
def compiles(monkeypatch, tmp_path):
    """Names of the packages compiled (calls of the C compiler) from now on, in a fresh cache."""
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))
    calls = []
    build = compile_cache._build

    def counting(pkg, *args, **kwargs):
        calls.append(pkg.name)
        return build(pkg, *args, **kwargs)

    monkeypatch.setattr(compile_cache, "_build", counting)
    return calls


def test_new_initial_state_compiles_nothing_and_starts_there(compiles, tmp_path):
    first, second = pendulum(0.3).build(), pendulum(0.1).build()
    assert not np.allclose(first.q0, second.q0)
    # the premise: the same functions (a length rounded differently would be another model)
    assert all(first.functions[f].serialize() == second.functions[f].serialize() for f in SYSTEM_FUNCTIONS)
    nc.simulate(first, t_end=0.1, dt=0.01, method="stepper", kernels="flat")
    assert compiles == ["swing"]

    run = nc.simulate(second, t_end=1.0, dt=0.001, method="stepper", kernels="flat")
    assert run.info["kernels"] == "flat"
    assert compiles == ["swing"], "the second initial state compiled the package again"
    np.testing.assert_array_equal(run.q[0], second.q0)

    # independent reference: IDAS through CasADi's VM (no generated C) from the same state
    ref = nc.simulate(second, t_end=1.0, dt=0.001, method="idas", backend="vm", rtol=1e-10, atol=1e-12)
    assert compiles == ["swing"]
    angle = np.arctan2(run.q[:, 0], -run.q[:, 1])
    angle_ref = np.arctan2(ref.q[:, 0], -ref.q[:, 1])
    assert abs(angle[0] - 0.1) < 1e-15 and np.ptp(angle) > 0.19      # swings from +0.1 past -0.09
    np.testing.assert_allclose(angle, angle_ref, atol=2e-5)


def test_initial_state_is_only_in_the_data_file(tmp_path):
    a = nc.generate(pendulum(0.3).build(), tmp_path / "a")
    b = nc.generate(pendulum(0.1).build(), tmp_path / "b")
    build = a.manifest["build"]
    assert build["data"] == ["swing_data.c"] and "swing_data.c" in build["sources"]
    differ = {rel for rel in a.manifest["files"] if (a.path / rel).read_bytes() != (b.path / rel).read_bytes()}
    library = set(compile_cache.library_sources(build) + build["headers"])
    assert "swing_data.c" in differ and not differ & library, differ & library
    data = (b.path / "swing_data.c").read_text()
    assert all(repr(float(x)) in data for x in b.manifest["metadata"]["q0"])
