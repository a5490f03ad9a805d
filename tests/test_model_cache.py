"""The store of built models (ncgen.codegen.model_cache): a model read back equals a fresh
build of the same file, a changed file or option misses, a damaged or foreign entry is
rebuilt, and the store can be turned off."""
from __future__ import annotations

import json
import pickle
import shutil
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.cli.common import load_model
from ncgen.codegen import model_cache
from ncgen.model.model import ReadOnlyList

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.fixture
def store(tmp_path, monkeypatch):
    """An empty store of its own (``$NCGEN_CACHE_DIR`` in the test's directory)."""
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv(model_cache.ENV, raising=False)
    return tmp_path / "cache" / "models"


def entries(store: Path) -> list[Path]:
    """The store's entries but the systems read from model files (``<key>-system.model``,
    tested in tests/test_model_store.py) and the functions made after a model was stored
    (``<key>-fn-<name>.model``, :func:`function_entries`)."""
    return sorted(p for p in store.glob("*.model") if not p.name.endswith("-system.model")
                  and "-fn-" not in p.name) if store.is_dir() else []


def function_entries(store: Path, key: str) -> set[str]:
    """The names of the functions stored beside the model ``key``."""
    return {p.name[len(key) + 4:-len(".model")] for p in store.glob(f"{key}-fn-*.model")}


def fresh(path, monkeypatch, **options):
    """The model built from ``path`` without the store."""
    with monkeypatch.context() as m:
        m.setenv(model_cache.ENV, "0")
        return load_model(str(path), **options)


def assert_same_model(a, b):
    """Same metadata, and every function of ``model.functions`` gives the same values at
    random arguments (1e-12)."""
    for name in ("name", "coordinate_names", "constraint_names", "input_names", "parameter_names",
                 "member_names", "marker_names", "contact_names", "joint_names", "redundant", "contact_model"):
        assert getattr(a, name) == getattr(b, name), name
    for name in ("q0", "v0", "lam0", "a0", "p0", "gravity", "M"):
        assert np.array_equal(np.asarray(getattr(a, name)), np.asarray(getattr(b, name))), name
    assert (a.t0, a.baumgarte, a.nq, a.nc, a.dof) == (b.t0, b.baumgarte, b.nq, b.nc, b.dof)
    assert sorted(a.functions) == sorted(b.functions) and a.functions
    rng = np.random.default_rng(7)
    for name, f in a.functions.items():
        g = b.functions[name]
        for _ in range(3):
            args = [rng.standard_normal(f.size_in(i)) for i in range(f.n_in())]
            for x, y in zip(f.call(args), g.call(args), strict=True):
                x, y = np.array(x), np.array(y)
                assert x.shape == y.shape
                scale = max(1.0, float(np.max(np.abs(y), initial=0.0)))
                assert np.allclose(x, y, rtol=0, atol=1e-12 * scale, equal_nan=True), name
    assert a.content_hash == b.content_hash


@pytest.mark.parametrize("name", ["slider_crank", "heavy_top"])
def test_stored_model_equals_a_fresh_build(store, monkeypatch, name):
    path = EXAMPLES / f"{name}.toml"
    first = load_model(str(path))
    assert len(entries(store)) == 1 and first.data.store_key is not None
    again = load_model(str(path))               # read back: a new object, nothing built
    assert again is not first and again.data.store_key == first.data.store_key
    assert_same_model(again, fresh(path, monkeypatch))
    with pytest.raises(AttributeError):          # as constant as a built model
        again.q0 = again.q0
    with pytest.raises(ValueError):
        again.q0[0] = 1.0
    assert isinstance(again.coordinate_names, ReadOnlyList)
    with pytest.raises(TypeError):
        again.coordinate_names.append("x")
    traj = nc.simulate(again, 0.05, 0.01)        # runs, and pickles by description as a built model does
    assert np.all(np.isfinite(traj.q))
    assert pickle.loads(pickle.dumps(again)).content_hash == again.content_hash


def test_stored_urdf_model_equals_a_fresh_build(store, monkeypatch):
    path = nc.robots.urdf_path("ur5")
    load_model(str(path))
    again = load_model(str(path))
    assert again.data.store_key is not None
    assert_same_model(again, fresh(path, monkeypatch))
    qj = np.linspace(-0.4, 0.5, len(again.joint_names))
    assert np.allclose(again.from_joint_space(qj)[0], fresh(path, monkeypatch).from_joint_space(qj)[0], atol=1e-12)


def test_stored_urdf_model_holds_no_sympy_and_its_tree_map_is_stored(store, monkeypatch):
    """Coordinate types are stored by name (their SymPy derivation is not in the entry) and the
    tree map, whose derivation needs them, is stored beside the model; it equals a fresh one."""
    from ncgen.codegen.tree_check import tree_function
    path = str(nc.robots.urdf_path("ur5"))
    load_model(path)
    model = load_model(path)
    key = model.data.store_key
    assert b"sympy" not in (store / f"{key}.model").read_bytes()
    f = tree_function(model)
    assert (store / f"{key}-joint-tree.model").is_file() and tree_function(model) is f
    built = fresh(path, monkeypatch)
    g = built.joint_space.tree_function(built.layout)
    rng = np.random.default_rng(3)
    for _ in range(3):
        qj, vj = rng.standard_normal(f.size1_in(0)), rng.standard_normal(f.size1_in(1))
        for x, y in zip(f(qj, vj), g(qj, vj), strict=True):
            assert np.allclose(np.array(x), np.array(y), rtol=0, atol=1e-12)


def test_changed_file_or_options_miss(store, tmp_path, monkeypatch):
    path = tmp_path / "model.toml"
    text = (EXAMPLES / "slider_crank.toml").read_text()
    path.write_text(text)
    first = load_model(str(path))
    masses = [line for line in text.splitlines() if line.strip().startswith("mass")]
    assert masses, "the example has a mass to change"
    path.write_text(text.replace(masses[0], masses[0].split("=")[0] + "= 7.25", 1))
    second = load_model(str(path))
    assert len(entries(store)) == 2
    assert not np.array_equal(np.asarray(second.M), np.asarray(first.M))
    assert_same_model(second, fresh(path, monkeypatch))
    third = load_model(str(path), share=False)   # another build option: another entry
    assert len(entries(store)) == 3 and third.nq >= second.nq


def damage(entry: Path, how: str) -> None:
    raw = entry.read_bytes()
    head, _, payload = raw.partition(b"\n")
    if how == "truncated":
        entry.write_bytes(raw[: len(raw) // 2])
    elif how == "garbage":
        entry.write_bytes(head + b"\n" + bytes(len(payload)))
    elif how == "empty":
        entry.write_bytes(b"")
    elif how == "foreign version":
        header = json.loads(head)
        header["ncgen"] = "0.0.0-other"
        entry.write_bytes(json.dumps(header).encode() + b"\n" + payload)
    elif how == "valid hash, bad pickle":
        import hashlib
        junk = b"\x80\x05not a pickle"
        header = json.loads(head)
        header.update(size=len(junk), sha256=hashlib.sha256(junk).hexdigest())
        entry.write_bytes(json.dumps(header).encode() + b"\n" + junk)


@pytest.mark.parametrize("how", ["truncated", "garbage", "empty", "foreign version", "valid hash, bad pickle"])
def test_damaged_or_foreign_entry_is_rebuilt(store, monkeypatch, capsys, how):
    path = EXAMPLES / "slider_crank.toml"
    load_model(str(path))
    [entry] = entries(store)
    damage(entry, how)
    raw = entry.read_bytes()
    capsys.readouterr()
    again = load_model(str(path))
    assert "building it again" in capsys.readouterr().err
    assert_same_model(again, fresh(path, monkeypatch))
    assert entry.read_bytes() != raw and model_cache.load(again.data.store_key) is not None   # stored again, whole


def test_store_off_and_clear(store, monkeypatch):
    path = EXAMPLES / "slider_crank.toml"
    monkeypatch.setenv(model_cache.ENV, "0")
    model = load_model(str(path))
    assert entries(store) == [] and model.data.store_key is None
    monkeypatch.setenv(model_cache.ENV, "1")
    load_model(str(path))
    assert len(entries(store)) == 1
    stored = len(list(store.glob("*.model")))       # the model's entry and its file's system
    assert stored == 2 and model_cache.clear() == stored and not store.exists()


def test_system_keyed_by_description(store, monkeypatch):
    system = nc.System.from_toml(EXAMPLES / "slider_crank.toml")
    first = model_cache.build_system(system)
    again = model_cache.build_system(nc.System.from_toml(EXAMPLES / "slider_crank.toml"))
    assert again is not first and len(entries(store)) == 1
    assert_same_model(again, system.build())
    model_cache.build_system(system, share=False)
    assert len(entries(store)) == 2


def test_unwritable_store_still_builds(store, monkeypatch, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(blocker))
    model = load_model(str(EXAMPLES / "slider_crank.toml"))
    assert model.data.store_key is None and model.nq > 0


def test_a_long_chains_mass_matrix_is_stored_by_its_nonzeros(store, monkeypatch):
    """A large, mostly zero array (the dense M of a chain of 150 bars: 450² entries, 1.3 % of
    them nonzero) is stored by its nonzeros and read back bit for bit; a crafted one keeps its
    ``-0.0`` and NaN, and a dense one is stored as it is."""
    def chain():
        s = nc.System("chain150")
        start = s.ground.point((0.0, 0.0, 0.0))
        for k in range(1, 151):
            start = s.add_bar(f"bar{k}", coords="rr", mass=0.1, ends=[start, (0.1 * k, 0.0, 0.0)]).end(1)
        return s

    model = chain().build()
    assert len(entries(store)) == 1
    again = chain().build()                                         # read back
    M = np.asarray(model.M)
    assert again is not model and len(model_cache._pickle({"M": M})) < M.nbytes / 20
    assert np.array_equal(np.asarray(again.M).view(np.uint64), M.view(np.uint64))
    sparse = np.zeros((300, 300))
    sparse[3, 5], sparse[7, 1], sparse[299, 299] = -0.0, np.nan, 2.5
    dense = np.random.default_rng(1).random((300, 300))
    for a in (sparse, dense):
        payload = model_cache._pickle({"a": a})
        assert (len(payload) < 1000) == (a is sparse)
        b = pickle.loads(payload)["a"]
        assert b.flags.c_contiguous and np.array_equal(b.view(np.uint64), a.view(np.uint64))


def test_derived_function_is_stored_beside_the_model(store, monkeypatch):
    import casadi as ca
    path = EXAMPLES / "slider_crank.toml"
    load_model(str(path))
    model = load_model(str(path))
    calls = []

    def build():
        calls.append(1)
        q = ca.SX.sym("q", model.nq)
        return ca.Function("half_phi", [q], [0.5 * model.functions["phi"](0, q, model.p0)])

    f = model_cache.derived_function(model, "half-phi", build)
    g = model_cache.derived_function(load_model(str(path)), "half-phi", build)
    assert calls == [1]
    q = model.q0 + 0.1
    assert np.allclose(np.array(g(q)).ravel(), 0.5 * model.phi(q), rtol=0, atol=1e-15)
    assert np.array_equal(np.array(f(q)), np.array(g(q)))
    shutil.rmtree(store)
    model_cache.derived_function(model, "half-phi", build)    # the store gone: derived again
    assert calls == [1, 1]


def test_warnings_of_the_build_are_given_again_when_read_back(store):
    from test_reliability_redundancy import distance_drive
    with pytest.warns(UserWarning, match=r"dropping redundant constraints d\.drive"):
        first = model_cache.build_system(distance_drive(1.0))
    with pytest.warns(UserWarning, match=r"dropping redundant constraints d\.drive"):
        again = model_cache.build_system(distance_drive(1.0))
    assert again is not first and again.data.store_key == first.data.store_key
    assert again.redundant == first.redundant == ["d.drive"] and again.dof == 1


@pytest.mark.slow      # the UR5 run three times through the CLI; fast: test_stored_urdf_model_equals_a_fresh_build,
#                       test_stored_urdf_model_holds_no_sympy_and_its_tree_map_is_stored
def test_cli_run_of_a_stored_urdf_model_equals_a_fresh_run(store, tmp_path, monkeypatch):
    """``ncgen simulate robot.urdf --kernels flat`` (joint space, the model's own loop): the
    second run reads the model and its joint-space ODE from the store and gives the trajectory
    of a run with the store off."""
    from ncgen.cli import main
    urdf = str(nc.robots.urdf_path("ur5"))
    runs = {}
    for label, env in (("first", "1"), ("stored", "1"), ("off", "0")):
        monkeypatch.setenv(model_cache.ENV, env)
        out = tmp_path / f"{label}.npz"
        assert main(["simulate", urdf, "--t-end", "0.05", "--kernels", "flat", "-o", str(out)]) in (0, None)
        runs[label] = np.load(out)
    monkeypatch.setenv(model_cache.ENV, "1")
    key = load_model(urdf).data.store_key
    assert {p.name for p in entries(store)} == {f"{key}{what}.model" for what in ("", "-joint-ode", "-joint-tree")}
    for key in ("t", "q", "v"):
        assert np.array_equal(runs["stored"][key], runs["first"][key]), key
        assert np.allclose(runs["stored"][key], runs["off"][key], rtol=0, atol=1e-12), key


def test_least_recently_used_entries_go_beyond_the_size_limit(store, monkeypatch):
    import os
    import time
    paths = [EXAMPLES / f"{name}.toml" for name in ("slider_crank", "double_pendulum", "cartpole")]
    for path in paths:
        load_model(str(path))
    used = [model_cache._path(model_cache.file_key(str(p), params=[], contacts="smooth", share=True,
                                                   floating_base=False, mjcf_contacts=False)) for p in paths]
    now = time.time()
    for entry, age in zip(used, (100, 50, 10)):
        os.utime(entry, (now - age, now - age))
    load_model(str(paths[0]))                    # read: now the most recently used
    sizes = [entry.stat().st_size for entry in used]
    monkeypatch.setattr(model_cache, "MAX_BYTES", sizes[0] + sizes[2] + 1)
    model_cache._prune(store, keep=used[2])      # as after writing the third
    assert [entry.is_file() for entry in used] == [True, False, True]
    monkeypatch.setattr(model_cache, "MAX_BYTES", 0)
    model_cache._prune(store, keep=used[2])      # never the entry just written
    assert [entry.is_file() for entry in used] == [False, False, True]


def test_functions_made_after_the_store_are_stored_beside_the_model(store, monkeypatch):
    """A model is stored with what its build made; ``poses`` (its maker needs the members'
    derivations) is made on its first use, in a later process as here, stored then, and read
    back by the next one without being made again; it equals a fresh build's bit for bit."""
    from ncgen.model import function_set
    path = str(EXAMPLES / "slider_crank.toml")
    made = []
    monkeypatch.setattr(function_set, "HOOKS", [made.append])
    first = load_model(path)
    key = first.data.store_key
    assert "poses" not in first.functions.made() and function_entries(store, key) == set()
    made.clear()
    second = load_model(path)
    R, p = second.functions["poses"](second.q0)
    assert made == ["poses"] and function_entries(store, key) == {"poses"}
    made.clear()
    third = load_model(path)
    R3, p3 = third.functions["poses"](third.q0)
    assert made == []                   # read from its entry, not made
    monkeypatch.setattr(function_set, "HOOKS", [])
    Rf, pf = fresh(path, monkeypatch).functions["poses"](first.q0)
    for x, y in ((R, Rf), (p, pf), (R3, Rf), (p3, pf)):
        assert np.array_equal(np.array(x), np.array(y))
    model_cache.clear()
    assert not store.exists()


def _bits(x) -> np.ndarray:
    """The float64 bit patterns of a CasADi output (dense)."""
    return np.ascontiguousarray(np.array(x, dtype=np.float64)).view(np.uint64)


@pytest.mark.parametrize("path", ["chain.toml", "fourbar_planar.toml", "panda", "falling_chain.toml"])
def test_every_sx_function_the_store_writes_reads_back_bit_for_bit(store, monkeypatch, path):
    """The store writes SX functions without reading them back (CasADi's SX serialisation is a
    list of scalar instructions): every SX function it writes for a chain, a four-bar, the
    Panda URDF and a contact example — the model's own entry, the functions stored beside it
    as they are made, the tree map — read back from disk in a new load evaluates bit for bit as
    the function that was written, at random inputs."""
    from ncgen.codegen.tree_check import tree_function

    file = str(nc.robots.urdf_path("panda") if path == "panda" else EXAMPLES / path)
    built = load_model(file)
    key = built.data.store_key
    written = {name: built.functions[name] for name in built.functions}      # the unmade ones stored now
    assert function_entries(store, key) and set(function_entries(store, key)) < set(written)
    if path == "panda":
        written["joint-tree"] = tree_function(built)
    made = []
    monkeypatch.setattr(model_cache.FunctionStore, "write", lambda self, name, f: made.append(name))
    again = load_model(file)
    read = {name: again.functions[name] for name in again.functions}
    assert made == []                   # every function read back: from the model's entry or beside it
    if path == "panda":
        read["joint-tree"] = tree_function(again)
    rng = np.random.default_rng(11)
    sx = [name for name, f in written.items() if f.class_name() == "SXFunction"]
    assert len(sx) >= 8, sx
    for name in sx:
        f, g = written[name], read[name]
        assert g is not f and g.class_name() == "SXFunction", name
        for _ in range(3):
            args = [rng.standard_normal(f.size_in(i)) for i in range(f.n_in())]
            for x, y in zip(f.call(args), g.call(args), strict=True):
                assert np.array_equal(_bits(x), _bits(y)), name
