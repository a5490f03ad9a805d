"""Built models cached from Python (``System.build()`` through the store of built models,
keyed by the system's content digest), systems read from model files kept in the store, and
``model.functions`` made lazily (issue 34, deliverable 5)."""
from __future__ import annotations

import math
import pickle
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.codegen import model_cache
from ncgen.model import function_set
from ncgen.model.digest import Unkeyable, digest_or_raise, system_digest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
G = 9.81


@pytest.fixture
def store(tmp_path, monkeypatch):
    """An empty store of its own, turned on."""
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv(model_cache.ENV, raising=False)
    return tmp_path / "cache" / "models"


def model_entries(store: Path) -> list[Path]:
    return sorted(p for p in store.glob("*.model") if "-" not in p.stem) if store.is_dir() else []


def pendulum(length: float, theta: float = 0.3) -> nc.System:
    """A uniform planar bar of 1 kg hinged at the origin, at ``theta`` above the +x axis."""
    s = nc.System("pendulum", gravity=(0.0, -G))
    s.add_bar("bar", coords="rr", mass=1.0,
              ends=[s.ground.point((0.0, 0.0)), (length * math.cos(theta), length * math.sin(theta))])
    return s


def angular_acceleration(model) -> float:
    """θ̈ of the pendulum from the model's accelerations at rest (the tip's ``(x ÿ − y ẍ)/L²``)."""
    a, _ = model.accel(model.q0, model.v0)
    x, y = model.q0[-2:]
    return float((x * a[-1] - y * a[-2]) / (x * x + y * y))


def built_without_store(system, monkeypatch, **options):
    with monkeypatch.context() as m:
        m.setenv(model_cache.ENV, "0")
        return system.build(**options)


def outputs(model, seed: int = 5) -> dict:
    """Every function of the model at the same random arguments."""
    rng = np.random.default_rng(seed)
    out = {}
    for name in sorted(model.functions):
        f = model.functions[name]
        args = [rng.standard_normal(f.size_in(i)) for i in range(f.n_in())]
        out[name] = [np.array(x) for x in f.call(args)]
    return out


def test_systems_differing_in_one_number_have_their_own_entries(store, monkeypatch):
    theta = 0.3
    models = {}
    for length in (1.0, 1.5):
        models[length] = pendulum(length, theta).build()
        assert models[length].data.store_key is not None
    assert models[1.0].data.store_key != models[1.5].data.store_key and len(model_entries(store)) == 2
    for length in (1.0, 1.5):
        again = pendulum(length, theta).build()               # read back, not built
        assert again is not models[length] and again.data.store_key == models[length].data.store_key
        # the closed form of a uniform rod about its end: θ̈ = −(3g / 2L) cos θ
        expected = -3 * G / (2 * length) * math.cos(theta)
        assert angular_acceleration(again) == pytest.approx(expected, rel=1e-12)
        off = built_without_store(pendulum(length, theta), monkeypatch)
        assert angular_acceleration(off) == pytest.approx(expected, rel=1e-12)
        assert again.content_hash == off.content_hash


def test_a_stored_model_gives_bit_identical_outputs(store):
    system = nc.System.from_toml(EXAMPLES / "slider_crank.toml")
    first = system.build()
    again = nc.System.from_toml(EXAMPLES / "slider_crank.toml").build()
    assert again.data.store_key == first.data.store_key
    a, b = outputs(first), outputs(again)
    assert a.keys() == b.keys()
    for name in a:
        assert all(np.array_equal(x, y, equal_nan=True) for x, y in zip(a[name], b[name], strict=True)), name
    for name in ("q0", "v0", "lam0", "a0", "M", "p0"):
        assert np.array_equal(getattr(first, name), getattr(again, name)), name
    assert first.content_hash == again.content_hash


def test_build_options_are_part_of_the_key(store):
    system = nc.System.from_toml(EXAMPLES / "slider_crank.toml")
    shared, unshared = system.build(), system.build(share=False)
    assert shared.data.store_key != unshared.data.store_key and unshared.nq > shared.nq


@pytest.mark.parametrize("how", ["truncated", "garbage", "foreign"])
def test_a_damaged_entry_is_rebuilt(store, monkeypatch, capsys, how):
    system = pendulum(1.0)
    key = system.build().data.store_key
    [entry] = model_entries(store)
    raw = entry.read_bytes()
    head, _, payload = raw.partition(b"\n")
    entry.write_bytes({"truncated": raw[: len(raw) // 2], "garbage": head + b"\n" + bytes(len(payload)),
                       "foreign": head.replace(nc.__version__.encode(), b"0.0.0-other") + b"\n" + payload}[how])
    capsys.readouterr()
    again = pendulum(1.0).build()
    assert "building it again" in capsys.readouterr().err
    assert again.data.store_key == key and model_cache.load(key) is not None   # stored again, whole
    assert angular_acceleration(again) == pytest.approx(-3 * G / 2 * math.cos(0.3), rel=1e-12)


def test_store_off(store, monkeypatch):
    monkeypatch.setenv(model_cache.ENV, "0")
    model = pendulum(1.0).build()
    system = nc.System.from_toml(EXAMPLES / "slider_crank.toml")
    assert model.data.store_key is None and not store.exists() and system.build().data.store_key is None
    monkeypatch.setenv(model_cache.ENV, "1")
    assert pendulum(1.0).build().data.store_key is not None and len(model_entries(store)) == 1


def test_a_python_callable_is_not_keyed(store):
    system = pendulum(1.0)
    system.add_force(nc.PointForce(system.member("bar"), (0.0, 0.0), force=lambda t: (0.0, 0.0)))
    with pytest.raises(Unkeyable, match=r"Python callable"):
        digest_or_raise(system)
    model = system.build()
    assert model.data.store_key is None and model_entries(store) == []
    assert angular_acceleration(model) == pytest.approx(-3 * G / 2 * math.cos(0.3), rel=1e-12)


def test_digest_is_the_content_and_building_leaves_it(store):
    system = nc.System.from_toml(EXAMPLES / "box_stack.toml")
    before = system_digest(system)
    system.build()
    assert system_digest(system) == before == system_digest(nc.System.from_toml(EXAMPLES / "box_stack.toml"))
    renamed = pendulum(1.0)
    renamed.name = "pendulum2"
    assert system_digest(renamed) != system_digest(pendulum(1.0))
    assert system_digest(pendulum(1.0)) != system_digest(pendulum(1.0 + 1e-15))


def test_a_model_file_is_read_once(store, monkeypatch, capsys):
    path = EXAMPLES / "double_pendulum.toml"
    first = nc.System.from_toml(path)
    [entry] = store.glob("*-system.model")
    with monkeypatch.context() as m:
        m.setattr("ncgen.model.toml_io.system_from_toml", lambda *a, **k: pytest.fail("parsed again"))
        again = nc.System.from_toml(path)
    assert again is not first and system_digest(again) == system_digest(first)
    assert again.build().content_hash == built_without_store(first, monkeypatch).content_hash
    entry.write_bytes(entry.read_bytes()[:100])                 # damaged: parsed again, stored again
    capsys.readouterr()
    assert system_digest(nc.System.from_toml(path)) == system_digest(first)
    assert "building it again" in capsys.readouterr().err
    nc.System.from_toml(path.read_text())                       # text: parsed, not stored
    assert list(store.glob("*-system.model")) == [entry]


def test_functions_are_made_on_first_access(store, monkeypatch):
    monkeypatch.setenv(model_cache.ENV, "0")
    made = []
    monkeypatch.setattr(function_set, "HOOKS", [made.append])
    model = pendulum(1.0).build()
    built = set(made)
    assert {"Minv", "dae", "ode", "alg", "energy", "poses", "markers", "mass"}.isdisjoint(built), built
    assert model.phi(model.q0).shape == (1,) and set(made) == built     # Φ was made by the build already
    model.functions["dae"]
    assert set(made) - built == {"dae"}                             # its primitives were there
    assert set(model.functions) >= {"Minv", "dae", "poses"} and "Minv" not in made


def test_lazy_functions_survive_the_store_and_pickling(store):
    model = nc.System.from_toml(EXAMPLES / "slider_crank.toml").build()
    again = nc.System.from_toml(EXAMPLES / "slider_crank.toml").build()
    assert again.functions.made() == ()                            # read back: each deserialised on use
    assert np.array_equal(again.A(again.q0), model.A(model.q0)) and again.functions.made() == ("A",)
    T, V = again.energy(again.q0, again.v0)
    assert np.isfinite(T) and np.isfinite(V) and "energy" in again.functions.made()
    round_trip = pickle.loads(pickle.dumps(model))
    assert round_trip.content_hash == model.content_hash


def test_a_stored_model_is_lazy_and_what_a_run_made_is_read_back_by_the_next(store, monkeypatch):
    """The command line and ``System.build`` store a model alike: the functions its build made
    (``A``), the others lazy (``dae``, ``poses``: no composite or member derivation paid for
    before a run asks for it); what one process makes is stored beside the model and read back,
    not made, by the next (a later run derives nothing that an earlier one derived)."""
    from ncgen.cli.common import load_model
    path = str(EXAMPLES / "slider_crank.toml")
    load_model(path)
    cli = load_model(path)                                      # read back
    python = [nc.System.from_toml(path).build() for _ in range(2)][1]
    stored = lambda model, name: model.functions._makers[name].func is function_set.deserialized  # noqa: E731
    for model in (cli, python):
        assert stored(model, "A") and not stored(model, "dae") and not stored(model, "poses")
    cli.functions["poses"], cli.functions["dae"]            # made here, stored beside the model
    made = []
    monkeypatch.setattr(model_cache.FunctionStore, "write", lambda self, name, f: made.append(name))
    later = load_model(path)
    later.functions["poses"], later.functions["dae"]
    assert made == [] and later.data.store_key == cli.data.store_key      # read back, not made
    assert np.array_equal(python.energy(python.q0, python.v0), cli.energy(cli.q0, cli.v0))


@pytest.mark.parametrize("example", ["boxes", pytest.param("box_stack", marks=pytest.mark.slow)])   # fast: boxes
def test_generated_c_does_not_depend_on_the_store(store, monkeypatch, tmp_path, example):
    """``nc.generate`` writes the same bytes for a model built afresh and for the same model
    read back from the store of built models (whose functions are other CasADi objects of the
    same expressions): the nonsmooth contact kernels per element included."""
    from ncgen.assembly import build as assembly_build

    path = EXAMPLES / f"{example}.toml"
    monkeypatch.setenv(model_cache.ENV, "0")
    fresh = nc.System.from_toml(path).build(contacts="nonsmooth")
    nc.generate(fresh, tmp_path / "fresh")
    monkeypatch.delenv(model_cache.ENV)
    nc.System.from_toml(path).build(contacts="nonsmooth")          # built and stored
    monkeypatch.setattr(assembly_build, "build_model", lambda *a, **k: pytest.fail("built again, not read back"))
    stored = nc.System.from_toml(path).build(contacts="nonsmooth")
    assert stored.data.store_key is not None
    nc.generate(stored, tmp_path / "stored")
    files = sorted(p.relative_to(tmp_path / "fresh") for p in (tmp_path / "fresh").rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(tmp_path / "stored") for p in (tmp_path / "stored").rglob("*") if p.is_file())
    assert any("pair" in (tmp_path / "fresh" / f).read_text() for f in files if f.suffix == ".c")
    different = [str(f) for f in files if (tmp_path / "fresh" / f).read_bytes() != (tmp_path / "stored" / f).read_bytes()]
    assert different == []
