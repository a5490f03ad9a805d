"""``ncgen derive`` and ``ncgen --help``."""
import os
import shutil
import subprocess
import sys

import pytest

from natural_helpers import ALL_TYPES, IDS
from ncgen.cli import SUBCOMMANDS, main


#: One body, one bar and the point of each dimension (ruvw, ru, r; ruv, rr, r) in the fast tier; the other
#: types (7–25 s each on a loaded 2-core machine) take the same path, in the slow tier (their formulas are
#: checked per type in the fast tier by tests/test_member.py).
SLOW_TYPES = {(3, "rrrr"), (3, "rrrw"), (3, "rrvw"), (3, "rr"), (2, "rrv"), (2, "rrr"), (2, "ru")}


@pytest.mark.parametrize("dim,name", [pytest.param(*t, marks=pytest.mark.slow) if t in SLOW_TYPES else t
                                      for t in ALL_TYPES], ids=IDS)
def test_derive_every_type_and_format(capsys, dim, name):
    for fmt in ("text", "markdown", "latex"):
        assert main(["derive", name, "--dim", str(dim), "--format", fmt]) == 0
        out = capsys.readouterr().out
        assert f"{dim}D" in out and name in out
        if fmt == "latex":
            assert out.lstrip().startswith("%") and r"\end{document}" in out


def test_default_is_3d_text(capsys):
    assert main(["derive", "rrvw"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("Natural coordinates: 3D body rrvw\n")


def test_output_file_is_written_whole(tmp_path, capsys):
    target = tmp_path / "d.md"
    target.write_text("old")
    assert main(["derive", "ru", "--format", "markdown", "-o", str(target)]) == 0
    captured = capsys.readouterr()
    assert captured.out == "" and "wrote" in captured.err
    assert main(["derive", "ru", "--format", "markdown"]) == 0
    assert target.read_text() == capsys.readouterr().out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.md"]     # no temporary file left


def test_unknown_type_exits_2_listing_valid_types(capsys):
    assert main(["derive", "ruvx"]) == 2
    err = capsys.readouterr().err
    assert "unknown TYPE 'ruvx' for --dim 3" in err
    assert "valid types for --dim 3: ruvw (body), rrvw (body), rrrw (body), rrrr (body), ru (bar), rr (bar), r (point)" in err
    assert "Traceback" not in err


def test_type_of_the_other_dimension(capsys):
    assert main(["derive", "ruvw", "--dim", "2"]) == 2
    err = capsys.readouterr().err
    assert "'ruvw' is a 3D type" in err and "valid types for --dim 2: ruv (body)" in err
    assert main(["derive", "rrv"]) == 2
    assert "add --dim 2" in capsys.readouterr().err


def test_bad_options_exit_2(capsys):
    assert main(["derive", "ru", "--format", "pdf"]) == 2
    assert "invalid choice: 'pdf'" in capsys.readouterr().err
    assert main(["derive", "ru", "--dim", "4"]) == 2
    assert main(["derive"]) == 2
    assert main([]) == 2
    assert "SUBCOMMAND" in capsys.readouterr().err


@pytest.mark.slow      # SE(3)'s derivation rendered; fast: test_derive_every_type_and_format, tests/test_teaching.py
#                       (the reports)
def test_se3(capsys):
    assert main(["derive", "se3", "--format", "markdown"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("# ") and "Ad" in out
    assert main(["derive", "se3", "--dim", "2"]) == 2
    assert "three-dimensional" in capsys.readouterr().err


def test_help_teaches(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    for name, cmd in SUBCOMMANDS.items():
        assert name in out and cmd.help in out
    assert main(["derive", "--help"]) == 0
    out = capsys.readouterr().out
    assert "examples:" in out and "ncgen derive ruvw --format latex -o ruvw.tex" in out
    assert "2D types (--dim 2): ruv (body)" in out


def test_every_subcommand_documents_itself():
    for cmd in SUBCOMMANDS.values():
        assert cmd.help and cmd.description and cmd.examples.strip().startswith(f"ncgen {cmd.name}")


def test_entry_point_subprocess(tmp_path):
    exe = shutil.which("ncgen")
    cmd = [exe] if exe else [sys.executable, "-m", "ncgen.cli"]
    env = {**os.environ, "PYTHONIOENCODING": "utf-8"}
    ok = subprocess.run(cmd + ["derive", "rr", "--dim", "2"], capture_output=True, text=True, env=env, timeout=120)
    assert ok.returncode == 0 and ok.stdout.startswith("Natural coordinates: 2D bar rr")
    bad = subprocess.run(cmd + ["derive", "nope"], capture_output=True, text=True, env=env, timeout=120)
    assert bad.returncode == 2 and "valid types for --dim 3" in bad.stderr and "Traceback" not in bad.stderr
