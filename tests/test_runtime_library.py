"""One compiled package per model serves IDAS, the stepper and the kernels."""
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.runtime import library
from ncgen.runtime.stepper_library import load_stepper

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.fixture(scope="module")
def model():
    return nc.System.from_toml(EXAMPLES / "double_pendulum.toml").build()


def test_idas_and_stepper_share_one_library(model, monkeypatch):
    built = []
    real = library.compile_package
    monkeypatch.setattr(library, "compile_package", lambda *a, **k: built.append(1) or real(*a, **k))
    idas = nc.simulate(model, t_end=0.05, dt=0.01, method="idas", backend="compiled")
    step = nc.simulate(model, t_end=0.05, dt=0.01, method="stepper")
    assert idas.info["backend"] == "compiled" and step.info["backend"] == "compiled"
    assert len(built) == 1                                 # one package, compiled (or found in the disk cache) once
    assert load_stepper(model).library == str(library.compiled_model(model).library)
    f = library.compiled_functions(model, ["phi"])["phi"]
    assert f.is_a("External")
    np.testing.assert_allclose(np.array(f(model.t0, model.q0, model.p0)).ravel(), model.phi(model.q0), atol=0)
