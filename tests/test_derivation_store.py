"""The store of coordinate types' derivations (``ncgen/symbolic/derivation_store.py``): a
derivation read back equals the one derived (every attribute, as SymPy expressions), a damaged
entry is derived again, ``NCGEN_MODEL_CACHE=0`` turns the store off (issue 34: first runs)."""
from __future__ import annotations

import pytest
import sympy as sp

from ncgen.files import MODEL_CACHE_ENV
from ncgen.symbolic.coordinates import Derivation, coordinate_type
from ncgen.symbolic.derivation_store import entry_path, stored_derivation


@pytest.fixture
def store(tmp_path, monkeypatch):
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv(MODEL_CACHE_ENV, raising=False)
    return tmp_path / "derivations"


def same(a, b) -> bool:
    if isinstance(a, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if isinstance(a, sp.MatrixBase):
        return isinstance(b, sp.MatrixBase) and a.shape == b.shape and all(same(x, y) for x, y in zip(a, b))
    return a == b


def no_derivation(*args, **kwargs):
    raise AssertionError("derived again instead of read from the store")


@pytest.mark.parametrize("name, dim", [("rrvw", 3), ("ruv", 2), ("rr", 3)])
def test_a_stored_derivation_equals_the_derived_one(store, monkeypatch, name, dim):
    ct = coordinate_type(name, dim)
    derived = Derivation(ct)
    stored_derivation(ct, Derivation)                          # derived and stored
    assert entry_path(name, dim).is_file()
    monkeypatch.setattr(Derivation, "__init__", no_derivation)
    read = stored_derivation(ct, Derivation)
    assert read.ctype is ct and set(vars(read)) == set(vars(derived))
    different = [k for k, v in vars(derived).items() if not same(v, getattr(read, k))]
    assert different == []
    q = list(read.q)                                            # still SymPy: the mass matrix of a point
    assert read.M.shape == (len(q), len(q)) and read.Phi_q.shape[1] == len(q)


def test_a_damaged_entry_is_derived_again(store, capsys):
    ct = coordinate_type("rr", 2)
    path = entry_path("rr", 2)
    path.parent.mkdir(parents=True)
    path.write_bytes(b"not a pickle")
    found = stored_derivation(ct, Derivation)
    assert found.ctype is ct and "is damaged" in capsys.readouterr().err
    assert stored_derivation(ct, Derivation).ctype is ct and capsys.readouterr().err == ""


def test_another_types_entry_is_refused(store, capsys):
    stored_derivation(coordinate_type("rr", 2), Derivation)
    entry_path("rr", 2).rename(entry_path("ru", 2))
    found = stored_derivation(coordinate_type("ru", 2), Derivation)
    assert found.ctype is coordinate_type("ru", 2) and "is damaged" in capsys.readouterr().err


def test_a_payload_not_matching_its_checksum_is_never_unpickled(store, monkeypatch, capsys):
    ct = coordinate_type("rr", 2)
    stored_derivation(ct, Derivation)
    path = entry_path("rr", 2)
    raw = bytearray(path.read_bytes())
    raw[-3] ^= 0xFF                                             # one byte of the pickle changed
    path.write_bytes(bytes(raw))
    monkeypatch.setattr("pickle.loads", no_derivation)
    found = stored_derivation(ct, Derivation)
    assert found.ctype is ct and "is damaged" in capsys.readouterr().err


def test_store_off(store, monkeypatch):
    monkeypatch.setenv(MODEL_CACHE_ENV, "0")
    assert stored_derivation(coordinate_type("rr", 3), Derivation).ctype is coordinate_type("rr", 3)
    assert not store.exists()


def test_entries_of_other_sources_are_removed_when_one_is_written(store):
    store.mkdir(parents=True)
    old = store / "rr-3d-0123456789abcdef01234567.derivation"
    older = store / "rr-3d-0123456789abcdef01234567.pickle"            # the layout before headers
    other = store / "ru-3d-0123456789abcdef01234567.derivation"
    older.write_bytes(b"an entry without a header")
    old.write_bytes(b"from other sources")
    other.write_bytes(b"another type")
    stored_derivation(coordinate_type("rr", 3), Derivation)
    assert sorted(p.name for p in store.iterdir()) == sorted([entry_path("rr", 3).name, other.name])
