"""The stepper's KKT solves by the Schur complement in blocks of the constant M⁻¹
(ncgen/codegen/kkt_blocks.py, ``kkt_schur`` in templates/c/runtime/ncgen_rattle.h): the
blocks follow the bodies, and the motion equals the sparse-QR path's to round-off on a chain,
closed loops and a heap of rotating spheres with friction.  The fallback on a singular block
is tested in C (tests/c/test_rattle.c with -DKKT_SCHUR)."""
from __future__ import annotations

import shutil
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
import ncgen.codegen.kkt_blocks as kkt_blocks
from ncgen.assembly.stepper_equations import stepper_functions

ROOT = Path(__file__).resolve().parents[1]
QUICK_COMPILE = True             # gcc compiling each scene twice: -O0 (tests/conftest.py)
pytestmark = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                                reason="no C compiler")


def chain(n: int = 3):
    s = nc.System(f"kkt_chain{n}", gravity=(0.0, 0.0, -9.81))
    start = s.ground.point((0.0, 0.0, 0.0))
    for k in range(n):
        start = s.add_bar(f"b{k}", "rr", mass=1.0, ends=[start, (k + 1.0, 0.0, 0.2 * k)]).end(1)
    return s.build()


def example(name: str):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return nc.System.from_toml(ROOT / "examples" / name).build()


def heap(n: int):
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        import contact
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    return contact.heap(n, rotating=True)


def context(model) -> dict:
    return kkt_blocks.kkt_block_context(model, stepper_functions(model)[0].sparsity_out("K"))


def test_blocks_of_a_heap_are_its_bodies():
    """Rotating spheres ('ruvw', centre of mass at r): each body's u, v, w and its six intrinsic
    constraints form one block, each coordinate of r (no constraint) one of its own; forces
    independent of v, so Newton's matrix takes the blocks too."""
    model = heap(3)
    ctx = context(model)
    assert ctx["kkt_blocks"] and ctx["kkt_newton"]
    sizes = [(q1 - q0, c1 - c0) for q0, q1, c0, c1 in zip(ctx["kkt_q0"], ctx["kkt_q0"][1:], ctx["kkt_c0"],
                                                             ctx["kkt_c0"][1:])]
    assert sorted(sizes) == sorted([(1, 0)] * 9 + [(9, 6)] * 3)
    assert sorted(ctx["kkt_q"]) == list(range(model.nq)) and sorted(ctx["kkt_c"]) == list(range(model.nc))


def test_no_blocks_where_they_do_not_apply(monkeypatch):
    """A block above KKT_BLOCK_MAX constraints: the sparse QR; dampers: not in Newton's matrix."""
    monkeypatch.setattr(kkt_blocks, "KKT_BLOCK_MAX", 2)
    assert context(chain(3)) == {"kkt_blocks": False}
    monkeypatch.undo()
    assert context(example("fourbar_planar.toml"))["kkt_newton"] is False   # its damper acts on v


def run(model, t_end: float, dt: float, substeps: int):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tr = nc.simulate(model, t_end, dt, method="stepper", substeps=substeps, kernels="flat", newton_tol=1e-13)
    return np.asarray(tr.q), np.asarray(tr.v)


@pytest.mark.parametrize("make, t_end, dt, substeps", [
    (lambda: chain(3), 0.5, 0.05, 50),
    (lambda: example("fourbar_planar.toml"), 0.5, 0.05, 50),
    (lambda: example("slider_crank.toml"), 0.5, 0.05, 50),
    (lambda: heap(4), 0.3, 0.01, 10)], ids=["chain", "fourbar", "slider-crank", "heap"])
def test_schur_blocks_give_the_qr_motion(monkeypatch, make, t_end, dt, substeps):
    model = make()
    assert context(model)["kkt_blocks"]
    q, v = run(model, t_end, dt, substeps)
    monkeypatch.setattr(kkt_blocks, "KKT_BLOCK_MAX", 0)
    reference = make()
    assert context(reference) == {"kkt_blocks": False}
    q_qr, v_qr = run(reference, t_end, dt, substeps)
    assert np.abs(q - q_qr).max() <= 1e-11 * (1 + np.abs(q_qr).max())
    assert np.abs(v - v_qr).max() <= 1e-9 * (1 + np.abs(v_qr).max())
