"""Contact-implicit optimal control with spheres against boxes (ncgen.optim.contact_implicit):
every contact kind of the model layer either transcribed or refused by name; a sphere pushed
along a fixed box's top face against the block's closed form, replayed by the nonsmooth
stepper."""
import importlib.util
import inspect
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import OptimizationError
from ncgen.model import capsule_contacts, contacts
from ncgen.optim.contact_implicit import SUPPORTED_KINDS

QUICK_COMPILE = True             # its replays' time is gcc compiling their scenes: -O0 (tests/conftest.py)


def _example(name):
    path = Path(__file__).resolve().parent.parent / "examples" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# ------------------------------------------------------------------ refusals, every kind
def _body(s, name, z):
    return s.add_body(name, mass=1.0, inertia=np.eye(3) * 0.01, position=(0, 0, z))


def _tetrahedron(path):
    path.write_text("v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 0.1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    return str(path)


#: One contact of each kind no transcription handles yet, on a body 1 m above the floor (or
#: apart from a second body): ``kind -> (make(system, body, other, tmp_path), a point contact's name)``.
UNHANDLED = {
    "MeshPlane": (lambda s, b, o, tmp: nc.MeshPlane(b, mesh=_tetrahedron(tmp / "t.obj"), name="c"), "c.vertex0"),
    "BoxBox": (lambda s, b, o, tmp: nc.BoxBox(b, (0.1, 0.1, 0.1), o, (0.1, 0.1, 0.1), name="c"), "c.a_corner0"),
    "CapsuleSphere": (lambda s, b, o, tmp: nc.CapsuleSphere(b, sphere_radius=0.05, capsule=o, radius=0.05,
                                                             length=0.2, name="c"), "c"),
    "CylinderSphere": (lambda s, b, o, tmp: nc.CylinderSphere(b, sphere_radius=0.05, cylinder=o, radius=0.05,
                                                               length=0.2, name="c"), "c"),
    "CapsuleCapsule": (lambda s, b, o, tmp: nc.CapsuleCapsule(b, 0.05, 0.2, o, 0.05, 0.2, name="c"), "c.a_end0"),
    "CapsuleBox": (lambda s, b, o, tmp: nc.CapsuleBox(b, 0.05, 0.2, box=o, size=(0.1, 0.1, 0.1), name="c"),
                   "c.end0"),
}


def _attachable_kinds():
    """The ``kind`` of every contact class a user attaches (not the point contacts the
    elements build for themselves)."""
    built_by_elements = (contacts.ShapePoint, contacts.BoxCorner, contacts.EdgeContact, capsule_contacts.CapsulePoint)
    kinds = set()
    for module in (contacts, capsule_contacts):
        for _, cls in inspect.getmembers(module, inspect.isclass):
            if (issubclass(cls, contacts.Contact) and cls.__module__ == module.__name__
                    and cls.kind != "Contact" and not issubclass(cls, built_by_elements)):
                kinds.add(cls.kind)
    return kinds


def test_every_contact_kind_is_transcribed_or_refused():
    """A new contact kind must join SUPPORTED_KINDS (with a solved test) or UNHANDLED."""
    kinds = _attachable_kinds()
    assert kinds == set(SUPPORTED_KINDS) | set(UNHANDLED), kinds ^ (set(SUPPORTED_KINDS) | set(UNHANDLED))
    assert not set(SUPPORTED_KINDS) & set(UNHANDLED)


@pytest.mark.parametrize("kind", sorted(UNHANDLED))
def test_unhandled_contact_kinds_are_refused_by_name(kind, tmp_path):
    make, point = UNHANDLED[kind]
    s = nc.System("refused", gravity=(0, 0, -9.81))
    b, o = _body(s, "b", 1.0), _body(s, "o", 2.0)
    s.add_contact(make(s, b, o, tmp_path))
    model = s.build(contacts="nonsmooth")
    assert model.contacts[0]["type"] == kind
    with pytest.raises(OptimizationError, match=rf"no optimal-control transcription handles the contact\(s\) "
                                                rf"'{point}' \({kind}"):
        nc.OptimalControl(model, N=4, t_final=1.0)


# ------------------------------------------------------------------ a sphere on a box
RADIUS, TOP = 0.05, 0.3                 # the sphere's radius and the height of the box's top face (m)


def sphere_on_box(block, dim):
    """The block of examples/block_push.py as a sphere of radius 0.05 m resting on the top
    face of a box fixed to the ground (1.2 m long, its top at 0.3 m), pushed along x from
    x = −D/2 to D/2: the gap and normal come from the box's face (SphereBox)."""
    at = (lambda x: (x, TOP + RADIUS)) if dim == 2 else (lambda x: (x, 0.0, TOP + RADIUS))
    s = nc.System(f"sphere_on_box{dim}", gravity=(0, -block.G) if dim == 2 else (0, 0, -block.G))
    ball = s.add_point("ball", mass=block.MASS, position=at(-block.DISTANCE / 2))
    ball.add_marker("centre", (0.0,) * dim)
    s.add_force(nc.PointForce(ball, (0.0,) * dim, force=ca.vertcat(s.add_input("push"), *[0] * (dim - 1))))
    size = (1.2, 2 * TOP) if dim == 2 else (1.2, 0.4, 2 * TOP)
    s.add_contact(nc.SphereBox(ball, radius=RADIUS, size=size, mu=block.MU, name="table"))
    return s.build(contacts="nonsmooth"), at


@pytest.mark.parametrize("dim", [2, pytest.param(3, marks=pytest.mark.slow)])
# 3D slow; fast: dim=2 (the same transcription; 3D adds the polyhedral cone's 4 directions)
def test_sphere_pushed_along_a_box_face_matches_the_block_closed_form(dim):
    """The least-effort push sliding the sphere along the face (T = 0.6 s: sliding
    throughout) is the block's closed form (the step is exact for piecewise-constant
    accelerations): pushes to 1e-6, normal force m g, the sphere on the face, every pair
    complementary; replayed by the nonsmooth stepper (steps T/N/10) it ends at the target."""
    block = _example("block_push")
    model, at = sphere_on_box(block, dim)
    T, N = 0.6, block.N
    ocp = nc.OptimalControl(model, N=N, t_final=T)
    if dim == 3:
        assert ocp.transcription.settings["directions"] == 4
    ocp.final(marker=("ball.centre", at(block.DISTANCE / 2)), v=0)
    ocp.minimize_effort()
    sol = ocp.solve("rest")
    push, cost = block.closed_form(T)
    assert np.max(np.abs(sol.u[:N, 0] - push)) < 1e-6 * np.max(np.abs(push))
    assert T / N * np.sum(sol.u[:N, 0] ** 2) == pytest.approx(cost, rel=1e-6)
    assert np.allclose(sol.contact_force[:, 0], block.MASS * block.G, rtol=1e-6)
    assert np.max(np.abs(sol.q[:, dim - 1] - (TOP + RADIUS))) < 1e-9        # on the face throughout
    assert np.max(np.abs(sol.q[:, 1:dim - 1]), initial=0.0) < 1e-9          # no sideways drift (3D)
    assert sol.complementarity_residual < 1e-6
    sim = nc.simulate(model, T, T / N, u=sol.u, hold="zoh", method="stepper", substeps=10)
    assert np.max(np.abs(sim.q[-1] - sol.q[-1])) < 1e-6
    assert np.max(np.abs(sim.q[:, dim - 1] - (TOP + RADIUS))) < 1e-9


# ------------------------------------------------------------------ a pusher and a box
@pytest.fixture(scope="module")
def pusher_box():
    ex = _example("pusher_box")
    model = ex.build()
    return ex, model, ex.problem(model).solve("rest")


@pytest.mark.slow      # fast: test_sphere_pushed_along_a_box_face_matches_the_block_closed_form (SphereBox, the same transcription)
def test_pusher_brings_the_box_to_its_pose(pusher_box):
    """The pusher's sphere meets the box's face (a SphereBox on the moving box), the box slides
    on the floor and ends at the target at rest, upright and on the floor throughout; every
    pair complementary; over an interval where the box slides forward with no floor impulse at
    its start, its momentum changes by the pusher's impulse at its start and push less
    Coulomb's sliding friction μ Σ f_N of the floor's corners (the RATTLE step is exact for
    constant forces on the box's translation)."""
    ex, model, sol = pusher_box
    assert sol.complementarity_residual < 1e-6
    assert np.max(np.abs(sol.marker("box.centre")[-1] - (ex.BOX_X + ex.DISTANCE, ex.BOX / 2))) < 1e-8
    assert np.max(np.abs(sol.v[-1])) < 1e-8
    for marker in ("box.centre", "box.front"):
        assert np.max(np.abs(sol.marker(marker)[:, 1] - ex.BOX / 2)) < 1e-8
    pushing, moving = ex.phases(model, sol)
    assert pushing.any() and moving.any()
    assert not pushing[0]                                       # it starts GAP away
    floor = [i for i, c in enumerate(model.contacts) if c["name"].startswith("floor.")]
    push = ex.contact_index(model, "push")
    x = sol.marker("box.centre")[:, 0]
    vx = sol.v[:, model.coordinate_names.index("box.r_i.x")]
    h = ex.T / ex.N
    checked = 0
    for k in range(ex.N):
        if x[k + 1] - x[k] > 1e-6 and not np.any(sol.contact_impulse[k, floor] > 1e-9):
            force = sol.contact_force[k, push] - ex.MU_FLOOR * sol.contact_force[k, floor].sum()
            change = sol.contact_impulse[k, push] + h * force
            assert ex.BOX_MASS * (vx[k + 1] - vx[k]) == pytest.approx(change, abs=1e-8)
            checked += 1
    assert checked >= 3


@pytest.mark.slow      # fast: test_sphere_pushed_along_a_box_face_matches_the_block_closed_form (replay of a SphereBox optimum)
def test_pusher_box_replays_in_the_nonsmooth_stepper(pusher_box):
    """The optimal push held over each step, simulated at T/N/20: the box ends within 0.1 mm
    of the optimum (5.2e-6 m measured; the optimum's strike falls on a node)."""
    ex, model, sol = pusher_box
    sim = ex.replay(model, sol)
    assert np.max(np.abs(sim.marker("box.centre")[-1] - sol.marker("box.centre")[-1])) < 1e-4
