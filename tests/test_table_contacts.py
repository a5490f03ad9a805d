"""Nonsmooth contacts on the element tables (issue 34): the contact library's pair kinds
between canonical sides (``ncgen.assembly.pair_kinds.table_kinds``, ``canonical_map``) give
each contact element's rows as the model's own per-element kernels (the flat rows with the
numbers built in) do; a new contact model of shipped kinds is stepped with no compiler on PATH
and creates no energy; the shipped contact examples and the 20-sphere heap step on the tables as
on their compiled packages (slow: those packages compile for minutes); what the tables do not
cover is named."""
from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from test_contact_pairs import shapes_system

import ncgen as nc
from ncgen.assembly.pair_kernels import pair_kernels
from ncgen.assembly.pair_kinds import pair_kind, table_kinds
from ncgen.codegen.compiler import CANDIDATES
from ncgen.codegen.contact_tables import contact_arrays, uncovered_contacts
from ncgen.codegen.model_tables import UnsupportedElements
from ncgen.runtime.table_stepper import stepper_kernels
from no_compiler import run_without_compiler

ROOT = Path(__file__).resolve().parent.parent
HAVE_CC = any(shutil.which(c) for c in CANDIDATES) or bool(os.environ.get("CC"))


def planar_scene():
    """Planar shapes: a box body on the ground, a ball (point) on it, a bar's end sphere."""
    s = nc.System("planar_contacts", gravity=(0.0, -9.81))
    box = s.add_body("box", coords="rrv", mass=1.0, inertia=0.02, position=(0.0, 0.1))
    ball = s.add_point("ball", mass=0.2, position=(0.05, 0.3))
    bar = s.add_bar("bar", coords="rr", mass=0.3, ends=[(0.4, 0.3), (0.7, 0.35)])
    s.add_contact(nc.BoxPlane(box, size=(0.3, 0.2), mu=0.4, name="box_floor"))
    s.add_contact(nc.SphereBox(ball, None, 0.05, box=box, size=(0.3, 0.2), mu=0.3, name="ball_box"))
    s.add_contact(nc.SpherePlane(bar, (0.3, 0.0), 0.02, mu=0.5, name="bar_floor"))
    return s


def canonical_rows(model, element, arrays, e, ql):
    """``(g, W)`` of element ``e`` at its local coordinates ``ql`` as the contact library's C
    (``tab_pair_eval``) forms them: each point contact's kind on the canonical coordinates
    ``B q`` of its two sides, its rows mapped back by ``B``."""
    a, dim, kinds = arrays["arrays"], model.dim, table_kinds()
    pi = a["pair_int"][8 * e:8 * e + 8]
    n = (pi[3], pi[4])
    qs = (ql[:n[0]], ql[n[0]:])
    maps = [np.zeros((a["cm_n"][2 * e + s], n[s])) for s in range(2)]
    for s in range(2):
        nz = slice(a["cm_ptr"][2 * e + s], a["cm_ptr"][2 * e + s + 1])
        np.add.at(maps[s], (a["cm_row"][nz], a["cm_col"][nz]), a["cm"][nz])
    qc = [maps[s] @ qs[s] for s in range(2)]
    g, W = np.zeros(element.count), np.zeros((element.count * dim, n[0] + n[1]))
    for j in range(element.count):
        k = pi[1] + j
        sa = a["pk_swap"][k]
        gk, Wc = pair_kind(*kinds[a["pk_kind"][k]]).plain(np.concatenate([qc[sa], qc[1 - sa]]),
                                                          a["pk_c"][a["pk_c_ptr"][k]:a["pk_c_ptr"][k + 1]])
        g[j], Wc = float(gk), np.asarray(Wc, float)
        off = 0
        for side in (sa, 1 - sa):
            if a["mu"][k] > 0:
                rows = slice(j * dim, (j + 1) * dim)
            else:                       # frictionless: the tangent rows stay zero
                rows, Wc = slice(j * dim, j * dim + 1), Wc[:1]
            base = 0 if side == 0 else n[0]
            W[rows, base:base + n[side]] += Wc[:, off:off + qc[side].size] @ maps[side]
            off += qc[side].size
    return g, W


SCENES = {"box_stack": lambda: nc.System.from_toml(ROOT / "examples" / "box_stack.toml"),
          "falling_chain": lambda: nc.System.from_toml(ROOT / "examples" / "falling_chain.toml"),
          "shapes": shapes_system, "planar": planar_scene}


@pytest.mark.parametrize("scene", sorted(SCENES))
def test_canonical_kinds_give_the_per_model_element_rows(scene):
    """Every contact element's gaps and dense rows W from the library's kinds on canonical
    sides equal the model's per-element kernels (its flat gap and contact Jacobian rows, or
    its kinds between its own coordinate types) to 1e-12 relative, at 10 random
    configurations near q0 (bodies of types ruvw, rrvw, points, bars; frictionless rows zero)."""
    model = SCENES[scene]().build(contacts="nonsmooth")
    assert uncovered_contacts(model) == []
    pairs, arrays = pair_kernels(model), contact_arrays(model)
    rng = np.random.default_rng(7)
    for _ in range(10):
        q = np.asarray(model.q0, float) + 0.02 * rng.standard_normal(model.nq)
        for e, el in enumerate(pairs.elements):
            ql = np.array([q[i] if i >= 0 else c for i, c in
                           zip(el.idx_a + el.idx_b, np.concatenate([el.const_a, el.const_b]))])
            g_ref, W_ref = (np.asarray(x, float) for x in
                            pairs.functions[2 * el.kernel + 1](ql[:len(el.idx_a)], ql[len(el.idx_a):], model.p0))
            g, W = canonical_rows(model, el, arrays, e, ql)
            scale = 1.0 + np.max(np.abs(W_ref))
            np.testing.assert_allclose(g, g_ref.ravel(), rtol=0, atol=1e-12 * (1 + np.max(np.abs(g_ref))))
            np.testing.assert_allclose(W, W_ref.reshape(W.shape), rtol=0, atol=1e-12 * scale, err_msg=el.name)


def test_uncovered_contacts_are_named():
    """A smooth contact law and a plane carried by a member are named by the refusal."""
    smooth = shapes_system("shapes_smooth").build()
    assert stepper_kernels(smooth, "auto") == "flat"
    with pytest.raises(UnsupportedElements, match="smooth contact law"):
        stepper_kernels(smooth, "tables")
    s = nc.System("carried_plane")
    a = s.add_body("a", mass=1.0, inertia=np.eye(3) * 0.01, position=(0, 0, 0.5))
    p = s.add_point("p", mass=0.5, position=(0, 0, 0.7))
    s.add_contact(nc.SpherePlane(p, None, 0.05, plane=a, normal=(0, 0, 1), point=(0, 0, 0.1), name="on_a"))
    with pytest.raises(UnsupportedElements, match="contact 'on_a'.*no pair kind"):
        stepper_kernels(s.build(contacts="nonsmooth"), "tables")


CHILD = r"""
import json
import numpy as np
import ncgen as nc
from no_compiler import forbid_compiler
from ncgen.runtime.table_library import load_contact_library
forbid_compiler()
load_contact_library()              # the library found in the cache, loaded
out = {}
rng = np.random.default_rng(3)
s = nc.System("nocc_pile")
r = 0.03 + 0.01 * rng.random()
box = s.add_body("box", mass=1.1, inertia=np.diag([0.01, 0.012, 0.015]), position=(0.0, 0.0, 0.06))
s.add_contact(nc.BoxPlane(box, size=(0.3, 0.2, 0.1), mu=0.4, name="box_floor"))
for k in range(3):
    b = s.add_point(f"ball{k}", mass=0.2, position=(0.05 * k - 0.05, 0.01 * k, 0.2 + 0.1 * k))
    s.add_contact(nc.SphereBox(b, None, r, box=box, size=(0.3, 0.2, 0.1), mu=0.3, name=f"ball{k}_box"))
    s.add_contact(nc.SpherePlane(b, None, r, name=f"ball{k}_floor"))
model = s.build(contacts="nonsmooth")
traj = nc.simulate(model, 0.6, 0.01, method="stepper", substeps=10)
e = traj.energy
out["pile"] = {"kernels": traj.info["kernels"], "complete": bool(traj.info["complete"]),
               "created": float(np.max(e - e[0])), "lost": float(e[0] - e[-1]), "E0": float(abs(e[0])),
               "z_min": float(np.min(traj.q[:, model.layout.member_indices("ball0")[2]]))}
print(json.dumps(out))
"""


@pytest.mark.skipif(not HAVE_CC, reason="no C compiler to build the contact library")
def test_a_new_contact_model_steps_with_no_compiler(tmp_path):
    """Once the contact library is cached (its one compile, ≈ 20 CPU-s per cache), a new pile
    of a box and three balls on the ground (random radius) is built and stepped with no compiler
    on PATH: the tables' stepper, the impacts dissipate (no energy created beyond 1e-9 relative),
    the balls stay above the floor (z ≥ r − 1e-8)."""
    from ncgen.runtime.table_library import load_contact_library

    load_contact_library()
    run = run_without_compiler(CHILD, tmp_path)["pile"]
    assert run["kernels"] == "tables" and run["complete"], run
    assert run["created"] <= 1e-9 * run["E0"], run
    assert run["lost"] > 0, run
    assert run["z_min"] > 0.03 - 1e-8, run


def _one_step(stepper, model, q, v, t, h):
    P = np.zeros((1, stepper.nd))
    Q, V, _, _, status, _, _ = stepper.simulate(q, v, t, h, 1, 1, None, model.p0, 1e-10, 12, 4, P)
    assert status == 0
    return Q[0], V[0], P[0]


@pytest.mark.slow       # the per-model packages: gcc for 10-60 s each (the heap's for minutes)
@pytest.mark.parametrize("scene", ["falling_chain", "boxes", "box_stack", "heap20"])
def test_contact_scenes_step_as_their_packages(scene):
    """One step from each state of the package's 0.5 s run (h = 1 ms), by the tables and by the
    package: equal to 1e-12 relative in q, 1e-9 in v (measured ≤ 1.7e-12) and in each element's
    summed impulse; where the support is statically indeterminate (a box's four corners on a
    slope) the shares of its point contacts differ (4e-3 relative measured on boxes: the
    least-norm distribution is found to the solve's tolerance from Delassus matrices that
    differ at round-off, KKT solves here, M⁻¹ there), not what moves the bodies."""
    from ncgen.runtime.stepper_library import load_stepper
    from ncgen.runtime.table_stepper import table_stepper

    if scene == "heap20":
        import sys
        sys.path.insert(0, str(ROOT / "benchmarks"))
        from contact import heap
        model = heap(20, rotating=False)
    else:
        model = nc.System.from_toml(ROOT / "examples" / f"{scene}.toml").build(contacts="nonsmooth")
    tables, flat = table_stepper(model), load_stepper(model)
    first = contact_arrays(model)["arrays"]["pair_int"].reshape(-1, 8)[:, 1]   # each element's first contact

    def per_element(P):
        """The impulses summed over each element's point contacts."""
        return np.add.reduceat(P.reshape(-1, model.dim), first, axis=0).ravel()

    h, n = 1e-3, 500
    Q, V, *_ = flat.simulate(model.q0, model.v0, 0.0, h, n, 1, None, model.p0, 1e-10, 12, 4)
    worst = {"q": 0.0, "v": 0.0, "P": 0.0}
    for k in range(0, n - 1, 5):
        a, b = (_one_step(s, model, Q[k], V[k], (k + 1) * h, h) for s in (tables, flat))
        a, b = (*a[:2], per_element(a[2])), (*b[:2], per_element(b[2]))
        for name, x, y in zip("qvP", a, b):
            worst[name] = max(worst[name], float(np.max(np.abs(x - y)) / (1 + np.max(np.abs(y)))))
    assert worst["q"] < 1e-12, worst
    assert worst["v"] < 1e-9 and worst["P"] < 1e-9, worst



def _pile(name: str, inertia=(0.01, 0.012, 0.015)):
    """A box (a 'ruvw' body: its six rigid-body constraints) on the floor with three balls on
    it and beside it, friction everywhere (``inertia``: the box's principal moments)."""
    s = nc.System(name)
    box = s.add_body("box", mass=1.1, inertia=np.diag(inertia), position=(0.0, 0.0, 0.06))
    s.add_contact(nc.BoxPlane(box, size=(0.3, 0.2, 0.1), mu=0.4, name="box_floor"))
    for k in range(3):
        b = s.add_point(f"ball{k}", mass=0.2, position=(0.1 * k - 0.05, 0.01 * k, 0.16 + 0.05 * k))
        s.add_contact(nc.SphereBox(b, None, 0.03, box=box, size=(0.3, 0.2, 0.1), mu=0.3, name=f"ball{k}_box"))
        s.add_contact(nc.SpherePlane(b, None, 0.03, mu=0.5, name=f"ball{k}_floor"))
    return s.build(contacts="nonsmooth")


@pytest.mark.skipif(not HAVE_CC, reason="no C compiler to build the contact library")
def test_the_delassus_matrix_from_minv_equals_the_kkt_solves(monkeypatch):
    """On the tables the Delassus matrix comes from the constant M⁻¹ and the Schur complement of
    A M⁻¹ Aᵀ where M is regular (``schur``), as in the per-model package; forced off
    (``MINV_MAX_NQ = 0``) it comes from one KKT solve per active row.  The two give the same
    step from every state of a 0.3 s run of a pile (box with its constraints, balls landing on it,
    friction): q to 1e-12, v and the impulses to 1e-9 relative.  A flat body (I1 + I2 = I3: M
    singular) gets no M⁻¹ (``schur`` 0: the KKT solves) and its drop onto the floor creates no
    energy and ends at rest on it."""
    import ncgen.codegen.stepper_package as package
    from ncgen.runtime.table_stepper import table_stepper

    model = _pile("pile_schur")
    assert contact_arrays(model)["schur"] == 1
    schur = table_stepper(model)
    monkeypatch.setattr(package, "MINV_MAX_NQ", 0)
    plain_model = _pile("pile_kkt")
    assert contact_arrays(plain_model)["schur"] == 0
    kkt = table_stepper(plain_model)
    h, n = 1e-3, 300
    Q, V, *_ = schur.simulate(model.q0, model.v0, 0.0, h, n, 1, None, model.p0, 1e-10, 12, 4)
    worst, loaded = {"q": 0.0, "v": 0.0, "P": 0.0}, 0
    for k in range(0, n - 1, 3):
        a, b = (_one_step(s, model, Q[k], V[k], (k + 1) * h, h) for s in (schur, kkt))
        loaded += bool(np.any(a[2]))
        for name, x, y in zip("qvP", a, b):
            worst[name] = max(worst[name], float(np.max(np.abs(x - y)) / (1 + np.max(np.abs(y)))))
    assert loaded > 50, loaded                  # contacts loaded in most of the compared steps
    assert worst["q"] < 1e-12 and worst["v"] < 1e-9 and worst["P"] < 1e-9, worst
    monkeypatch.undo()
    flat = _pile("pile_flat", inertia=(0.01, 0.02, 0.03))
    assert contact_arrays(flat)["schur"] == 0
    traj = nc.simulate(flat, 0.5, 0.01, method="stepper", substeps=10, kernels="tables")
    e, z = traj.energy, traj.q[:, flat.layout.member_indices("box")[2]]
    assert traj.info["complete"] and np.max(e - e[0]) <= 1e-9 * abs(e[0]), np.max(e - e[0])
    assert abs(z[-1] - 0.05) < 1e-6 and np.max(np.abs(traj.v[-1])) < 1e-6, (z[-1], traj.v[-1])
