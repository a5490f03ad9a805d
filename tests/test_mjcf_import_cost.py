"""The cost of an MJCF import: each joint and force is checked in a context of its own
members (so adding n elements costs O(n), not O(n²): the quadratic parse of humanoid_CMU),
and a file read before comes from the store of built models without parsing, unless it or
a file it includes changed.  Timings: benchmarks/mjcf_import_time.py."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.codegen import model_cache
from ncgen.model import context as context_module
from ncgen.model import mjcf as mjcf_module

#: Test files covering every joint kind, a loop, actuators, tendons and contacts.
FORMS = ("sequences.xml", "loop_legs.xml", "actuators.xml", "tendons.xml", "contacts.xml")


def chain(n: int) -> str:
    """An MJCF chain of ``n`` capsules on hinges with springs (2n checked elements)."""
    body = ""
    for k in reversed(range(n)):
        body = (f'<body name="b{k}" pos="{0.0 if k == 0 else 0.2} 0 {1.0 if k == 0 else 0.0}">'
                f'<joint name="j{k}" axis="0 1 0" stiffness="1"/>'
                f'<geom type="capsule" fromto="0 0 0 0.2 0 0" size="0.02"/>{body}</body>')
    return f'<mujoco model="chain"><worldbody>{body}</worldbody></mujoco>'


def test_each_element_is_checked_among_its_own_members(monkeypatch):
    """Every check's context holds at most the two bodies the element joins (24 coordinates),
    whatever the length of the chain."""
    sizes = []
    original = context_module.Context.__init__

    def recording(self, system, layout):
        sizes.append(layout.nq)
        original(self, system, layout)

    monkeypatch.setattr(context_module.Context, "__init__", recording)
    system = nc.System.from_mjcf(chain(12))
    assert len(system.joints) == 12 and len(system.forces) == 12
    assert len(sizes) == 24 and max(sizes) == 24


def test_a_file_read_before_comes_from_the_store(tmp_path, monkeypatch):
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv(model_cache.ENV, raising=False)
    parts = tmp_path / "parts.xml"
    parts.write_text('<mujoco><default><joint damping="0.3"/></default></mujoco>')
    path = tmp_path / "arm.xml"
    path.write_text(chain(3).replace("<worldbody>", '<include file="parts.xml"/><worldbody>'))
    calls = []
    parse = mjcf_module.system_from_mjcf
    monkeypatch.setattr(mjcf_module, "system_from_mjcf", lambda *a, **k: calls.append(1) or parse(*a, **k))
    first = nc.System.from_mjcf(path)
    again = nc.System.from_mjcf(path)
    assert len(calls) == 1                                         # the second from the store
    assert again.to_toml() == first.to_toml() and again.joints[0].dynamics == {"damping": 0.3}
    assert np.array_equal(again.actuator_gear, first.actuator_gear) and again.frames.keys() == first.frames.keys()
    parts.write_text('<mujoco><default><joint damping="0.4"/></default></mujoco>')   # an included file changed
    changed = nc.System.from_mjcf(path)
    assert len(calls) == 2 and changed.joints[0].dynamics == {"damping": 0.4}


def test_the_warning_of_a_stored_file_is_given_again(tmp_path, monkeypatch):
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv(model_cache.ENV, raising=False)
    path = tmp_path / "fluid.xml"
    path.write_text(chain(2).replace("<worldbody>", '<option density="1.2"/><worldbody>'))
    for _ in range(2):
        with pytest.warns(mjcf_module.MjcfWarning, match=r"fluid\.xml:1 <option>: density"):
            nc.System.from_mjcf(path)


def test_first_import_of_every_form_needs_no_sympy(tmp_path):
    """An empty store, a fresh process: MJCF files with every joint kind (hinge, slide, ball,
    free and the joint sequences), leg loops closed by ``connect``, actuators of every kind,
    fixed and spatial tendons, and contacts are imported and built without importing SymPy
    (the coordinate types' formulas come shipped as generated data), so the first import of
    an arm costs about a second of CPU (``benchmarks/mjcf_import_time.py``)."""
    data = Path(__file__).parent / "data"
    code = ("import sys, warnings\nwarnings.simplefilter('ignore')\nimport ncgen as nc\n"
            f"for name in {FORMS!r}:\n"
            f"    system = nc.System.from_mjcf({str(data)!r} + '/' + name, contacts=name == 'contacts.xml')\n"
            "    assert system.build().dof > 0, name\n"
            "assert 'sympy' not in sys.modules, 'SymPy imported'\nprint('ok')")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[1]), "NCGEN_CACHE_DIR": str(tmp_path / "cache")}
    env.pop("NCGEN_MODEL_CACHE", None)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=tmp_path,
                         timeout=600)
    assert out.returncode == 0 and out.stdout.strip().endswith("ok"), out.stderr[-3000:]
