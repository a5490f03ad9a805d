"""``ncgen generate``: the package of a model file; bad input gives one clear message,
exit status 1 and nothing on disk."""
from pathlib import Path

import pytest

from ncgen.cli import main

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


@pytest.fixture(autouse=True)
def private_cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "ncgen-cache"))


def test_generates_the_shipped_package(tmp_path, capsys):
    assert main(["generate", str(EXAMPLES / "chain.toml"), "-o", str(tmp_path / "chain")]) == 0
    shipped = Path(__file__).resolve().parent.parent / "generated" / "chain"
    assert {p.name: p.read_bytes() for p in (tmp_path / "chain").iterdir()} == \
           {p.name: p.read_bytes() for p in shipped.iterdir()}
    assert "C package 'chain'" in capsys.readouterr().err


def test_compile(tmp_path, capsys):
    assert main(["generate", str(EXAMPLES / "heavy_top.toml"), "-o", str(tmp_path / "top"), "--compile",
                 "--cflags=-O0"]) == 0
    assert "compiled " in capsys.readouterr().err


def test_reroll_sets_which_functions_become_loops(tmp_path):
    """``--reroll 0`` loops every function with repeated blocks; ``--reroll none`` none."""
    import json

    sizes = {}
    for flag in ("0", "none"):
        out = tmp_path / flag
        assert main(["generate", str(EXAMPLES / "chain.toml"), "-o", str(out), "--reroll", flag]) == 0
        manifest = json.loads((out / "manifest.json").read_text())
        sizes[flag] = {f["name"]: f["n_instructions"] for f in manifest["functions"]}
    assert sizes["0"]["A"] < sizes["none"]["A"] and sizes["0"]["dae"] < sizes["none"]["dae"]


def test_bad_reroll_value_is_named(capsys):
    err = error_of(capsys, ["generate", str(EXAMPLES / "chain.toml"), "-o", "x", "--reroll", "many"], status=2)
    assert "--reroll" in err and "'many'" in err


def error_of(capsys, argv, status=1) -> str:
    assert main(argv) == status
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    return captured.err


@pytest.mark.parametrize("content,expected", [
    (None, "does not exist"),
    ("[system\nname = 'x'", "invalid TOML"),
    ("[system]\nname = 'x'\n[[members]]\nname = 'a'\nkind = 'bar'\nmas = 1.0\n", "members[0].mas: unknown key"),
    ("[system]\nname = 'x'\n[[members]]\nname = 'a'\nkind = 'bar'\nmass = 1.0\nends = [[0, 0, 0], [1, 0, 0]]\n"
     "velocity = [1.0, 0.0, 0.0]\n[[joints]]\ntype = 'Spherical'\nbetween = ['ground', 'a']\nat = [0, 0, 0]\n",
     "inconsistent initial velocities"),
])
def test_bad_model_files(tmp_path, capsys, content, expected):
    model = tmp_path / "m.toml"
    if content is not None:
        model.write_text(content)
    err = error_of(capsys, ["generate", str(model), "-o", str(tmp_path / "out")])
    assert err.startswith("ncgen generate: error: ") and expected in err
    assert str(model.name) in err
    assert not (tmp_path / "out").exists()


def test_failed_compile_leaves_nothing(tmp_path, capsys):
    err = error_of(capsys, ["generate", str(EXAMPLES / "heavy_top.toml"), "-o", str(tmp_path / "out"),
                            "--compile", "--cflags=-fno-such-flag-ncgen"])
    assert "C compilation failed" in err
    assert list(tmp_path.iterdir()) == []


def test_refuses_a_directory_that_is_not_a_package(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("mine")
    err = error_of(capsys, ["generate", str(EXAMPLES / "chain.toml"), "-o", str(tmp_path)])
    assert "not an ncgen package" in err
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"]


def test_help_has_examples(capsys):
    assert main(["generate", "--help"]) == 0
    out = capsys.readouterr().out
    assert "examples:" in out and "ncgen generate examples/chain.toml" in out
