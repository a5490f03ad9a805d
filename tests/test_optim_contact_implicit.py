"""Optimal control through nonsmooth contacts (ncgen.optim.contact_implicit): refusals of
what no transcription handles, settings checks, and solved problems against closed forms
and the nonsmooth stepper."""
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import OptimizationError, ProblemFileError


def _ball(contacts="nonsmooth", restitution=0.8, mu=0.0):
    s = nc.System("ball", gravity=(0, -9.81))
    b = s.add_point("ball", mass=1.0, position=(0, 1.0))
    b.add_marker("c", (0, 0))
    s.add_contact(nc.SpherePlane(b, radius=0.1, restitution=restitution, mu=mu, name="floor"))
    return s.build(contacts=contacts)


def _box_on_box():
    s = nc.System("boxes", gravity=(0, 0, -9.81))
    box = s.add_body("box", mass=1.0, inertia=np.eye(3) * 0.01, position=(0, 0, 0.2))
    s.add_contact(nc.BoxBox(box, (0.1, 0.1, 0.1), s.ground, (1, 1, 0.2), at_b=(0, 0, 0.0), name="on_table"))
    return s.build(contacts="nonsmooth")


@pytest.mark.parametrize("method", ["collocation", "shooting"])
def test_other_transcriptions_refuse_nonsmooth_contacts(method):
    model = _ball()
    with pytest.raises(OptimizationError, match=r"nonsmooth contacts \('floor' \(SpherePlane\)\).*as if they were absent"):
        nc.OptimalControl(model, N=10, t_final=1.0, method=method)


def test_unhandled_contact_kind_is_refused_by_name():
    model = _box_on_box()
    with pytest.raises(OptimizationError, match=r"no optimal-control transcription handles the contact\(s\) "
                                                r"'on_table\.a_corner0' \(BoxBox of element 'on_table'\)"):
        nc.OptimalControl(model, N=10, t_final=1.0)


def test_nonsmooth_model_defaults_to_contact_implicit_and_smooth_to_collocation():
    assert "contact-implicit" in repr(nc.OptimalControl(_ball(), N=4, t_final=1.0))
    assert "contact-implicit" not in repr(nc.OptimalControl(_ball("smooth"), N=4, t_final=1.0))
    with pytest.raises(OptimizationError, match="has no nonsmooth contacts"):
        nc.OptimalControl(_ball("smooth"), N=4, t_final=1.0, method="contact_implicit")


@pytest.mark.parametrize("settings, match", [
    ({"sigma_final": 0.0}, r"contacts\.sigma_final: expected a finite number > 0"),
    ({"sigma0": 1e-6, "sigma_final": 1e-3}, r"contacts\.sigma_final: expected at most sigma0"),
    ({"sigma_factor": 1.5}, r"contacts\.sigma_factor: expected a number in \(0, 1\)"),
    ({"step_lengths": "adaptive"}, r"contacts\.step_lengths: expected \"equal\" or \"free\""),
    ({"step_bounds": (2.0, 3.0)}, r"contacts\.step_bounds"),
    ({"directions": 3}, r"contacts\.directions"),
    ({"sigma": 1.0}, r"contacts: unknown setting\(s\) sigma"),
])
def test_contact_settings_are_checked(settings, match):
    with pytest.raises(OptimizationError, match=match):
        nc.OptimalControl(_ball(), N=4, t_final=1.0, contacts=settings)


def test_problem_file_contacts_table(tmp_path):
    from ncgen.optim.problem_file import problem_from_data
    ocp, _ = problem_from_data({"horizon": {"N": 4, "t_final": 1.0}, "contacts": {"step_lengths": "free"}},
                               _ball(), "p.toml")
    assert ocp.transcription.settings["step_lengths"] == "free"
    with pytest.raises(ProblemFileError, match=r"contacts\.tol"):
        problem_from_data({"contacts": {"tol": -1.0}}, _ball(), "p.toml")
