"""Contact pair kinds (``ncgen/assembly/pair_kinds.py``): one kernel per kind of point
contact with the pair's numbers as arguments, equal to the per-model element kernels with
the numbers built in (the rows of the model's flat ``gap`` and ``contact_jacobian``,
``ncgen/assembly/pair_kernels.py`` with ``KIND_CALLS`` off) at random configurations, their
normal rows the gap's derivative along the constraint manifold (central differences), and
the element kernels that call them (the default) equal to those with the numbers built in."""
from functools import lru_cache

import numpy as np
import pytest

import ncgen as nc
import ncgen.assembly.pair_kernels as pair_kernels_module
from ncgen.assembly.pair_kernels import pair_kernels
from ncgen.assembly.pair_kinds import KINDS, pair_kind, point_call
from test_contact_pairs import R_z, box_inertia, random_rotation, shapes_system


def rim_system():
    """Cylinders and a box against the floor (rim points), a body-fixed box and capsule."""
    s = nc.System("rims")
    a = s.add_body("a", mass=1.0, inertia=box_inertia(1.0, (0.2, 0.2, 0.1)), position=(0, 0, 0.5))
    b = s.add_body("b", coords="rrrw", mass=1.0, inertia=box_inertia(1.0, (0.2, 0.2, 0.1)), position=(1, 0, 0.5))
    s.add_contact(nc.CylinderPlane(a, radius=0.08, length=0.1, mu=0.3, name="can"))
    s.add_contact(nc.CapsulePlane(b, radius=0.03, length=0.2, rotation=R_z(0.3), mu=0.3, name="rod"))
    s.add_contact(nc.BoxPlane(b, size=(0.2, 0.1, 0.05), at=(0.01, 0, 0), mu=0.2, name="tile"))
    return s


def planar_system():
    """Discs, a rectangle on a rectangle and on the ground, a disc against a bar."""
    s = nc.System("planar_pairs", gravity=(0.0, -9.81))
    a = s.add_body("a", "ruv", mass=1.0, inertia=0.01, position=(0, 0.5))
    b = s.add_body("b", coords="rrv", mass=2.0, inertia=0.02, position=(1, 0.5))
    bar = s.add_bar("bar", mass=0.5, inertia=0.01, ends=((0, 1.0), (0.4, 1.2)))
    p = s.add_point("p", mass=0.5, position=(0, 1.0))
    s.add_contact(nc.BoxBox(a, (0.2, 0.1), b, (0.3, 0.2), mu=0.4, name="boxes"))
    s.add_contact(nc.BoxBox(b, (0.3, 0.2), s.ground, (2.0, 0.1), at_b=(0, -0.05), name="table"))
    s.add_contact(nc.SphereSphere(bar, (0.1, 0), 0.05, p, None, 0.04, mu=0.3, name="balls"))
    s.add_contact(nc.SphereBox(p, None, 0.04, box=a, size=(0.2, 0.1), mu=0.2, name="ball_box"))
    s.add_contact(nc.SpherePlane(bar, (0.2, 0.0), 0.03, mu=0.5, name="floor"))
    return s


def random_state(model, rng, spread):
    """A configuration on the constraint manifold (every member at a random pose)."""
    q = np.array(model.q0, float)
    for name, member in model.members.items():
        if model.dim == 3:
            R = random_rotation(rng) if member.kind == "body" else None
            if member.kind == "bar":
                R = random_rotation(rng)
            pose = (R, rng.uniform(-spread, spread, 3))
        else:
            t = rng.uniform(-np.pi, np.pi)
            pose = (np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]]) if member.kind != "point" else None,
                    rng.uniform(-spread, spread, 2))
        qm = member.rigid.q_from_pose(*pose)
        for i, x in zip(model.layout.member_indices(name), qm):
            if i is not None:
                q[i] = x
    return q


def _local(q, idx, const):
    return np.array([q[i] if i >= 0 else c for i, c in zip(idx, const)])


def flat_pair_kernels(model):
    """The per-model element kernels with the numbers built in (the model's flat rows)."""
    pair_kernels_module.KIND_CALLS = False
    try:
        return pair_kernels(model)
    finally:
        pair_kernels_module.KIND_CALLS = True


@lru_cache(maxsize=None)
def prepared(which):
    """The system ``which`` built with nonsmooth contacts, its per-model element kernels (by
    name) and table, and each point contact's call of its kind."""
    model = SYSTEMS[which]().build(contacts="nonsmooth")
    pairs = flat_pair_kernels(model)
    calls = {id(pc): point_call(pc, model.dim) for el in model.contact_elements for pc in el.point_contacts()}
    return model, pairs, {f.name(): f for f in pairs.functions}, calls


def calls_and_references(which, q):
    """Per point contact: its call, its coordinates in the kind's order, and the per-model
    kernel's gap and rows at ``q`` in the same columns (frictionless tangent rows zero)."""
    model, pairs, rows, calls = prepared(which)
    dim, out = model.dim, []
    for el, e in zip(model.contact_elements, pairs.elements):
        names = [m.name for m in el.members()]
        sides = [(_local(q, e.idx_a, e.const_a), 0), (_local(q, e.idx_b, e.const_b), len(e.idx_a))]
        g, W = (np.array(x) for x in rows[f"step_pair{e.kernel}_rows"](sides[0][0], sides[1][0], model.p0))
        for k, pc in enumerate(el.point_contacts()):
            call = calls[id(pc)]
            assert call is not None, pc
            qk, cols = [np.zeros(0)], []
            for m in call.members:
                if not m.is_ground:
                    ql, off = sides[names.index(m.name)]
                    qk.append(ql)
                    cols += range(off, off + ql.size)
            out.append((pc, call, np.concatenate(qk), g[k].item(), W[k * dim:(k + 1) * dim][:, cols], e.friction[k]))
    return out


SYSTEMS = {"shapes": shapes_system, "rims": rim_system, "planar": planar_system}


@pytest.mark.parametrize("which", sorted(SYSTEMS))
def test_kinds_equal_the_per_model_kernels(which):
    """Every point contact through its kind's kernel (numbers as arguments) gives the gap and
    the rows of the per-model element kernel (numbers built in) to 1e-12 relative, at 20
    random configurations from overlapping to apart; every kind of the table occurs."""
    model = prepared(which)[0]
    rng = np.random.default_rng(7)
    seen = set()
    for trial in range(20):
        q = random_state(model, rng, [0.1, 0.3, 1.0][trial % 3])
        for pc, call, qk, g, W, friction in calls_and_references(which, q):
            gk, Wk = (np.array(x) for x in call.kind.function(qk, call.numbers))
            if not friction:
                Wk[1:] = 0.0
            scale = max(1.0, abs(g), np.abs(W).max())
            assert abs(gk.item() - g) <= 1e-12 * scale, (pc.name, gk.item(), g)
            assert np.abs(Wk - W).max() <= 1e-12 * scale, (pc.name, np.abs(Wk - W).max())
            seen.add(call.kind.kind)
    expected = {"shapes": set(KINDS) - {"sphere_plane_rim"}, "rims": {"sphere_plane", "sphere_plane_rim"},
                "planar": {"box_corner", "sphere_sphere", "sphere_box", "sphere_plane"}}[which]
    assert seen == expected


def _tangent_basis(model, call, qk):
    """A basis of the sides' constraint manifold's tangent space at ``qk`` (columns)."""
    blocks, at = [], 0
    for m in call.members:
        if m.is_ground:
            continue
        n = m.ctype.nq
        A = m.rigid.phi_q(qk[at:at + n]) if m.ctype.n_phi else np.zeros((0, n))
        _, s, Vt = np.linalg.svd(A) if A.size else (None, np.zeros(0), np.eye(n))
        blocks.append(Vt[int(np.sum(s > 1e-9)):].T)
        at += n
    out = np.zeros((at, sum(b.shape[1] for b in blocks)))
    r = c = 0
    for b in blocks:
        out[r:r + b.shape[0], c:c + b.shape[1]] = b
        r, c = r + b.shape[0], c + b.shape[1]
    return out


@pytest.mark.parametrize("which", sorted(SYSTEMS))
def test_normal_rows_are_the_gap_s_derivative(which):
    """Each kind's normal row ``W_N`` is the derivative of its gap along the manifold: in the
    tangent directions ``T`` of the sides' intrinsic constraints, ``W_N T`` equals central
    differences of ``g(q + ε T)`` to 1e-6, wherever the gap is smooth there (differences at ε
    and ε/2 agree to 1e-8; near a switch of face, region or edge they do not); at least 80 % of
    the samples of each kind are checked."""
    model = prepared(which)[0]
    rng = np.random.default_rng(11)
    checked, total = {}, {}
    eps = 1e-6
    for trial in range(8):
        q = random_state(model, rng, [0.1, 0.3, 1.0][trial % 3])
        for pc, call, qk, g, W, friction in calls_and_references(which, q):
            f = call.kind.function
            gap = lambda x: float(f(x, call.numbers)[0])  # noqa: E731
            if abs(gap(qk)) > 1.0:                         # an edge crossing that is no contact (its band)
                continue
            T = _tangent_basis(model, call, qk)
            WN = np.array(f(qk, call.numbers)[1])[0]
            cd = np.array([(gap(qk + eps * t) - gap(qk - eps * t)) / (2 * eps) for t in T.T])
            cd2 = np.array([(gap(qk + eps / 2 * t) - gap(qk - eps / 2 * t)) / eps for t in T.T])
            total[call.kind.kind] = total.get(call.kind.kind, 0) + 1
            if np.abs(cd - cd2).max() > 1e-8:
                continue
            checked[call.kind.kind] = checked.get(call.kind.kind, 0) + 1
            assert np.abs(WN @ T - cd).max() <= 1e-6, (pc.name, WN @ T, cd)
    assert total and all(checked.get(k, 0) >= 0.8 * n for k, n in total.items()), (checked, total)


def test_one_kernel_per_kind_and_side_types():
    """Equal kinds share one kernel whatever their numbers: the 16 corners of two box pairs of
    other sizes between free bodies are one kernel per corner side (a body's corners against a
    body, one size-independent kernel); the kernel's size does not grow with the pair's."""
    s = nc.System("two_stacks")
    boxes = [s.add_body(f"b{k}", mass=1.0, inertia=box_inertia(1.0, (0.2, 0.2, 0.1)), position=(0, 0, 0.1 * k))
             for k in range(3)]
    s.add_contact(nc.BoxBox(boxes[0], (0.2, 0.2, 0.1), boxes[1], (0.3, 0.1, 0.1), name="low"))
    s.add_contact(nc.BoxBox(boxes[1], (0.3, 0.1, 0.1), boxes[2], (0.1, 0.1, 0.4), name="high"))
    model = s.build(contacts="nonsmooth")
    calls = [point_call(pc, 3) for el in model.contact_elements for pc in el.point_contacts()]
    assert len(calls) == 32 and {c.kind.name for c in calls} == {"pk_box_corner_ruvw_ruvw_3d"}
    assert len({c.numbers.tobytes() for c in calls}) == 32
    assert pair_kind("box_corner", "ruvw", "ruvw", 3) is calls[0].kind


@pytest.mark.parametrize("which", sorted(SYSTEMS))
def test_element_kernels_calling_the_kinds_equal_the_flat_ones(which):
    """The per-model element kernels as calls of the pair kinds (``KIND_CALLS``, the default:
    the C has one function per kind) give the gaps and rows of those with the numbers built in,
    to 1e-12 relative, at 10 random configurations; equal elements still share a kernel."""
    model, flat, flat_rows, _ = prepared(which)
    kinds = pair_kernels(model)
    assert all(f.name().startswith("step_pair") for f in kinds.functions)
    called = {g.name() for f in kinds.functions for g in f.find_functions()}
    assert called and all(n.startswith("pk_") for n in called)
    rows = {f.name(): f for f in kinds.functions}
    rng = np.random.default_rng(5)
    for trial in range(10):
        q = random_state(model, rng, [0.1, 0.3, 1.0][trial % 3])
        for e, ef in zip(kinds.elements, flat.elements, strict=True):
            args = (_local(q, e.idx_a, e.const_a), _local(q, e.idx_b, e.const_b), model.p0)
            g, W = (np.array(x) for x in rows[f"step_pair{e.kernel}_rows"](*args))
            g_ref, W_ref = (np.array(x) for x in flat_rows[f"step_pair{ef.kernel}_rows"](*args))
            gap = np.array(rows[f"step_pair{e.kernel}_gap"](*args))
            scale = max(1.0, np.abs(g_ref).max(), np.abs(W_ref).max())
            assert np.abs(g - g_ref).max() <= 1e-12 * scale and np.abs(gap - g_ref).max() <= 1e-12 * scale, e.name
            assert np.abs(W - W_ref).max() <= 1e-12 * scale, e.name
