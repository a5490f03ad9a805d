"""Constraints are dropped only when implied by the others near the configuration and
satisfied (issue 13, class 2; rule in ncgen.assembly.redundancy).  The references are the
geometry: a rigid bar's length fixes the distance of its two points, a chain held stretched
by a tether has one degree of freedom (rotation about the pivot), a parallelogram ladder has
one, and a four-bar with four parallel revolutes has three implied equations."""
import warnings

import numpy as np
import pytest

import ncgen as nc
from ncgen.assembly.check import check_system
from ncgen.assembly.redundancy import classify
from test_kinematics import _fourbar_3d_four_revolutes


def distance_drive(drive):
    """A bar hinged at the origin; a Distance drive between the origin and the bar's far end,
    1 m apart, which the bar's rigidity already fixes."""
    s = nc.System("dd", gravity=(0, -9.81))
    a = s.add_bar("a", mass=1.0, ends=[s.ground.point((0, 0)), (1, 0)])
    s.add_joint(nc.Distance(s.ground, a, at=[(0, 0), (1, 0)], drive=drive, name="d"))
    return s


def tethered_chain(angle):
    """Two unit bars from the origin, the second at ``angle`` to the first, and a tether
    between the origin and the far end (its initial length)."""
    s = nc.System("tether", gravity=(0, -9.81))
    a = s.add_bar("a", mass=1.0, ends=[s.ground.point((0, 0)), (1, 0)])
    tip = (1 + np.cos(angle), np.sin(angle))
    b = s.add_bar("b", mass=1.0, ends=[a.end(1), tip])
    s.add_joint(nc.Distance(s.ground, b, at=[(0, 0), tip], name="tether"))
    return s


def parallelogram_ladder(n, angle):
    """n parallelograms side by side: n + 1 unit cranks on ground pivots 2 m apart, all at
    ``angle``, their tips joined by n couplers (one degree of freedom)."""
    s = nc.System("ladder", gravity=(0, -9.81))
    tip = np.array([np.cos(angle), np.sin(angle)])
    cranks = [s.add_bar(f"crank{i}", mass=1.0, ends=[s.ground.point((2.0 * i, 0)), (2.0 * i, 0) + tip])
              for i in range(n + 1)]
    for i in range(n):
        s.add_bar(f"coupler{i}", mass=1.0, ends=[cranks[i].end(1), cranks[i + 1].end(1)])
    return s


def test_distance_drive_contradicting_a_rigid_bar_is_an_error_naming_it():
    with pytest.raises(nc.ModelError, match=r"d\.drive \(Φ = -24\) contradict"):
        distance_drive(5.0).build()
    report = check_system(distance_drive(5.0))             # `ncgen check` no longer says "consistent: yes"
    assert not report.ok and "d.drive" in report.error
    assert "consistent: no" in report.render()


def test_distance_drive_agreeing_with_the_bar_is_dropped():
    with pytest.warns(UserWarning, match=r"dropping redundant constraints d\.drive"):
        model = distance_drive(1.0).build()
    assert model.dof == 1 and model.redundant == ["d.drive"]


def test_stretched_tether_is_not_dropped():
    with pytest.raises(nc.ModelError, match=r"singular: the constraints tether\.distance"):
        tethered_chain(0.0).build()


def test_bent_tether_is_kept_and_holds():
    """Away from the singular position the tether is independent: DOF 1, and the simulated
    tether length stays at its initial value (the dropped-tether bug let it reach 1.91 m)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model = tethered_chain(0.3).build()
    assert model.dof == 1 and "tether.distance" in model.constraint_names
    traj = nc.simulate(model, t_end=0.5, dt=0.05, backend="vm")
    tip = traj.q[:, 2:4]                                  # b.r_j
    np.testing.assert_allclose(np.linalg.norm(tip, axis=1), np.linalg.norm(tip[0]), atol=1e-7)


def test_flat_parallelogram_ladder_keeps_its_couplers():
    with pytest.raises(nc.ModelError, match=r"singular: the constraints coupler0\.rigid\.uu, .*coupler9\.rigid\.uu"):
        parallelogram_ladder(10, 0.0).build()


def test_tilted_parallelogram_ladder_has_one_degree_of_freedom():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model = parallelogram_ladder(10, 0.4).build()
    assert nc.dof_report(model).dof == 1 and model.dof == 1


def test_truly_redundant_revolutes_are_still_dropped():
    """The classic overconstrained four-bar: the three dependent equations are implied."""
    with pytest.warns(UserWarning, match="dropping redundant constraints D.coincide.z, D.align.1, D.align.2"):
        model = _fourbar_3d_four_revolutes().build(share=False)     # the joint equations are what is dropped
    assert model.dof == 1


def test_classify_the_three_kinds():
    """The rule on explicit functions of q = (x, y): Φ = [x² + y² − 1, row] at (1, 0)."""
    def make(row):
        phi = lambda t, q: np.array([q[0] ** 2 + q[1] ** 2 - 1, row(q)])     # noqa: E731
        def jac(t, q, h=1e-7):
            return np.array([[(phi(t, q + h * e)[i] - phi(t, q - h * e)[i]) / (2 * h) for e in np.eye(2)]
                             for i in range(2)])
        return phi, jac
    q0 = np.array([1.0, 0.0])
    implied = classify(*make(lambda q: 2 * (q[0] ** 2 + q[1] ** 2 - 1)), q0, 0.0, [1])
    violated = classify(*make(lambda q: q[0] ** 2 + q[1] ** 2 - 4), q0, 0.0, [1])
    singular = classify(*make(lambda q: q[0] - 1), q0, 0.0, [1])          # tangent line at (1, 0)
    assert implied.droppable == [1] and not implied.violated and not implied.singular
    assert list(violated.violated) == [1] and violated.violated[1] == pytest.approx(-3)
    assert list(singular.singular) == [1]
