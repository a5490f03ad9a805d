"""A model's run-time data (``model.data``, :mod:`ncgen.model.data`) is one object per model,
outside the constant model, filled by the modules that own its slots."""
import gc
import weakref

import numpy as np

import ncgen as nc
from ncgen.model.data import ModelData, model_data
from ncgen.model.model import model_state, restored_model


def pendulum():
    s = nc.System("pendulum", gravity=(0, 0, -9.81))
    b = s.add_bar("b", coords="rr", mass=1.0, ends=[(0, 0, 0), (1, 0, 0)])
    s.add_joint(nc.Spherical(s.ground, b, at=(0, 0, 0)))
    return s.build()


def test_one_data_object_per_model_outside_its_state():
    """The data is kept on the model (``model._data``) but is no part of its stored state
    (:func:`~ncgen.model.model.model_state`) nor of what its pickle sends."""
    m1, m2 = pendulum(), pendulum()
    assert isinstance(m1.data, ModelData)
    assert m1.data is m1.data is model_data(m1)
    assert m1.data is not m2.data
    assert all(v is not m1.data for v in model_state(m1).values())
    assert isinstance(restored_model(model_state(m1)).data, ModelData)


def test_analysis_functions_are_kept_in_the_data():
    model = pendulum()
    assert model.data.functions == {}
    eq = nc.equilibrium(model)
    assert model.data.functions, "equilibrium builds its CasADi functions into model.data.functions"
    kept = dict(model.data.functions)
    eq2 = nc.equilibrium(model)
    assert all(model.data.functions[k] is f for k, f in kept.items())   # built once
    np.testing.assert_allclose(eq.q, eq2.q)


def test_the_data_goes_with_its_model():
    model = pendulum()
    ref = weakref.ref(model.data)
    del model
    gc.collect()
    assert ref() is None


def test_anything_but_a_model_is_refused_naming_what_it_is():
    """The doors read the model's data first: a string, None or a number in the model's
    place is refused with a ModelError that names it, not an AttributeError from inside."""
    import pytest
    from ncgen.errors import ModelError
    z = np.zeros(2)
    calls = {"aba": lambda m: nc.aba(m, z, z, z), "rnea": lambda m: nc.rnea(m, z, z, z),
             "inverse_dynamics": lambda m: nc.inverse_dynamics(m, z, z, z),
             "joint_forward_dynamics": lambda m: nc.joint_forward_dynamics(m, z, z),
             "model_data": model_data}
    for name, call in calls.items():
        for bad, shown in (("panda.urdf", "str 'panda.urdf'"), (None, "NoneType None"), (3, "int 3")):
            with pytest.raises(ModelError, match=f"expected an ncgen model .* got {shown}"):
                call(bad)
