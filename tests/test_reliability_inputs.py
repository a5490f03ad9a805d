"""Hostile input never gives a traceback, and every message names what is wrong (issue 13,
classes 3-5): one validation path (ncgen.validation, ncgen.model.expressions) for names,
numbers and expressions, used by the API, the TOML loader and the command line; user files
are never deleted; what killed runs leave behind is cleaned up."""
from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen import files
from ncgen.cli import main
from ncgen.errors import NcgenError
from ncgen.validation import MAX_NAME, as_scalar, as_system_name, name

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"

MODEL = """[system]
name = "{system}"
gravity = [0.0, -9.81]

[parameters]
k = {k}

[[members]]
name = "{member}"
kind = "bar"
coords = "rr"
mass = {mass}
ends = [{{ ground = [0.0, 0.0] }}, {end}]

[[forces]]
type = "Spring"
name = "spring"
between = ["ground", "{member}"]
at_a = [1.0, 1.0]
at_b = [0.5, 0.0]
k = {spring_k}
"""


def model_text(**kw) -> str:
    values = dict(system="hostile", k="2.0", member="bar", mass="1.0", end="[1.0, 0.0]", spring_k='"k"')
    values.update(kw)
    return MODEL.format(**values)


#: (TOML changes, what the message must contain)
BAD_MODELS = {
    "mass with 400 digits": (dict(mass="1" * 400), "members[0].mass: the number is too large"),
    "position 1e300": (dict(end="[1e300, 0.0]"), "members[0].ends[1][0]: expected a number of magnitude at most"),
    "k = 9**9**9**9": (dict(spring_k='"9**9**9**9"'), "forces[0].k: '9 ** 9 ** 9': the result is too large"),
    "k = 1/0": (dict(spring_k='"1/0"'), "forces[0].k: '1 / 0': division by zero"),
    "k = (-1)**0.5": (dict(spring_k='"(-1)**0.5"'), "forces[0].k: '(-1) ** 0.5': the result is complex"),
    "k = sqrt(-1)": (dict(spring_k='"sqrt(-1)"'), "forces[0].k: 'sqrt(-1)': the result is nan"),
    "k = log(0)": (dict(spring_k='"log(0)"'), "forces[0].k: 'log(0)': the result is -inf"),
    "parameter nan": (dict(k="nan"), "parameters.k: expected a finite number"),
    "parameter inf": (dict(k="inf"), "parameters.k: expected a finite number"),
    "negative stiffness": (dict(k="-5.0"), "force 'spring' (Spring): k = -5: expected a finite number >= 0"),
    "negative literal": (dict(spring_k="-5.0"), "force 'spring' (Spring): k: expected a number >= 0"),
    "300-character system name": (dict(system="s" * 300), "system name: expected an identifier"),
    "5000-character member name": (dict(member="m" * 5000), "bar name: expected an identifier"),
    "non-ASCII member name": (dict(member="stäbchen"), "the character 'ä' is not allowed"),
    "name starting with a digit": (dict(member="1bar"), "it starts with a digit"),
}


def run(capsys, argv, status):
    code = main(argv)
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err + captured.out
    assert code == status, captured.err
    return captured


@pytest.mark.parametrize("case", list(BAD_MODELS))
def test_bad_models_are_one_clear_message_in_check_and_simulate(tmp_path, capsys, case):
    """The same rule at load for `check` and `simulate` (a name `check` accepts is never
    refused later), naming the file and the key."""
    changes, expected = BAD_MODELS[case]
    path = tmp_path / "m.toml"
    path.write_text(model_text(**changes), encoding="utf-8")
    out = run(capsys, ["check", str(path)], 1)
    assert expected in out.out + out.err and str(path) in out.out + out.err
    err = run(capsys, ["simulate", str(path), "--t-end", "0.1", "-o", str(tmp_path / "x.npz"),
                       "--backend", "vm"], 1).err
    assert expected in err and err.startswith(f"ncgen simulate: error: {path}")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.toml"]


def test_non_utf8_file_is_named(tmp_path, capsys):
    path = tmp_path / "latin1.toml"
    path.write_bytes(model_text().encode() + "# café\n".encode("latin-1"))
    err = run(capsys, ["check", str(path)], 1).err
    assert f"{path}: not UTF-8 text: byte 0xe9 at line 22" in err


def test_utf8_bom_is_accepted(tmp_path, capsys):
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + model_text().encode())
    assert "consistent: yes" in run(capsys, ["check", str(path)], 0).out
    assert nc.System.from_toml("\ufeff" + model_text()).name == "hostile"


def test_names_one_rule():
    assert name("a" * MAX_NAME, "x") == "a" * MAX_NAME
    for bad in ("a" * (MAX_NAME + 1), "stäbchen", "1a", "", "a-b", "a b", "ℌ"):
        with pytest.raises(NcgenError, match="x: expected an identifier"):
            name(bad, "x")
    s = nc.System("s", gravity=(0, -9.81))
    for add in (lambda: s.add_parameter("ké", 1.0), lambda: s.add_input("k" * 65),
                lambda: s.add_bar("b" * 65, mass=1.0, ends=[(0, 0), (1, 0)]),
                lambda: nc.System("ß"), lambda: s.add_point("p", mass=1, position=(0, 0)).add_marker("é", (0, 0))):
        with pytest.raises(nc.ModelError, match="expected an identifier"):
            add()


def test_system_names_prefix_casadi_functions():
    """A system's name prefixes CasADi function names (``<system>_step``), which must start with
    a letter and have no ``__``: such names are refused when written, and names made from a file
    or a robot (``2dof_planar``) are made valid."""
    for bad, why in (("_x", "does not start with a letter"), ("a__b", "two underscores"), ("b_", "ends with '_'")):
        with pytest.raises(nc.ModelError, match=f"system name: .*{why}"):
            nc.System(bad)
    assert [as_system_name(s, "robot") for s in ("2dof_planar", "__a--b__", "", "ur5")] == \
        ["robot_2dof_planar", "a_b", "robot", "ur5"]
    urdf = ('<robot name="2dof-planar"><link name="base"/><link name="arm"><inertial><mass value="1"/>'
            '<inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>'
            '<joint name="j" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>'
            '<limit effort="1" velocity="1" lower="-1" upper="1"/></joint></robot>')
    model = nc.System.from_urdf(urdf).build()
    assert model.name == "robot_2dof_planar"
    x1 = nc.step_function(model, 0.01)(np.concatenate([model.q0, model.v0]), np.zeros(model.nu))
    assert np.all(np.isfinite(x1)) and np.max(np.abs(x1[:model.nq] - model.q0)) < 0.01


def test_numbers_one_rule():
    with pytest.raises(NcgenError, match="mass: the number is too large"):
        as_scalar(10**400, "mass")
    with pytest.raises(NcgenError, match="at most 1e\\+100"):
        as_scalar(1e300, "position")
    with pytest.raises(NcgenError, match="expected a number, got 'abc'"):
        as_scalar("abc", "k")


def test_run_arguments_are_named():
    model = nc.System.from_toml(EXAMPLES / "fourbar_planar.toml").build()
    cases = [(dict(t_end=np.nan), "t_end: expected a finite number, got nan"),
             (dict(t_end=np.inf), "t_end: expected a finite number, got inf"),
             (dict(t_end=1.0, t0=np.nan), "t0: expected a finite number, got nan"),
             (dict(t_end=1.0, dt=np.nan), "dt: expected a finite number"),
             (dict(t_end=1.0, dt=-1.0), "dt: expected a positive output step"),
             (dict(t_end=1.0, p={"k": np.nan}), "parameter 'k': expected finite numbers"),
             (dict(t_end=1.0, p={"k": "abc"}), "parameter 'k': expected numbers"),
             (dict(t_end=1.0, p=[np.nan]), "parameter 'k': expected finite numbers"),
             (dict(t_end=1.0, p={"k": -3.0}), "TorsionalSpring): k = -3: expected a finite number >= 0"),
             (dict(t_end=1e6, dt=1e-6), "(1,000,000,000,001 points) would need ")]
    for kw, expected in cases:
        kw.setdefault("dt", 0.1)
        with pytest.raises(NcgenError) as info:
            nc.simulate(model, **kw)
        assert expected in str(info.value), (kw, str(info.value))


def test_huge_grid_is_refused_from_the_cli(tmp_path, capsys):
    err = run(capsys, ["simulate", str(EXAMPLES / "fourbar_planar.toml"), "--t-end", "1e6", "--dt", "1e-6",
                       "-o", str(tmp_path / "x.npz")], 1).err
    assert re.search(r"would need [0-9.]+ TiB of memory", err) and "use a larger dt" in err


def test_internal_error_is_short_and_says_where_to_report(capsys, monkeypatch):
    import ncgen.cli as cli

    def boom(args, parser):
        raise RuntimeError("unexpected state")

    cli.build_parser()
    original = cli.SUBCOMMANDS["check"]
    monkeypatch.setitem(cli.SUBCOMMANDS, "check", original.__class__(**{**original.__dict__, "run": boom}))
    code = main(["check", "x.toml"])
    err = capsys.readouterr().err
    assert code == 70 and "Traceback" not in err
    assert "internal error (RuntimeError: unexpected state)" in err and "report it" in err and "--debug" in err
    assert main(["--debug", "check", "x.toml"]) == 70
    assert "Traceback" in capsys.readouterr().err


# ----------------------------------------------------------------- user data
def test_generate_keeps_the_users_files(tmp_path, capsys):
    out = tmp_path / "pkg"
    run(capsys, ["generate", str(EXAMPLES / "fourbar_planar.toml"), "-o", str(out)], 0)
    (out / "notes.md").write_text("my notes")
    (out / "results").mkdir()
    (out / "results" / "run.npz").write_bytes(b"data")
    (out / "fourbar_planar_main").write_bytes(b"built by make")        # a build product: ncgen's
    run(capsys, ["generate", str(EXAMPLES / "fourbar_planar.toml"), "-o", str(out)], 0)
    assert (out / "notes.md").read_text() == "my notes"
    assert (out / "results" / "run.npz").read_bytes() == b"data"
    assert not (out / "fourbar_planar_main").exists()
    (out / "main.c").write_text("edited")
    err = run(capsys, ["generate", str(EXAMPLES / "fourbar_planar.toml"), "-o", str(out)], 1).err
    assert "main.c were edited after generation" in err and (out / "main.c").read_text() == "edited"


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_killed_runs_leftovers_are_swept(tmp_path, capsys):
    host = files.temporary_name("x").split("-")[1]
    dead = tmp_path / f".pkg.tmp-{host}-{_dead_pid()}-abc123"
    dead.mkdir()
    (dead / "half.c").write_text("")
    alive = tmp_path / f".pkg.tmp-{host}-{os.getpid()}-abc123"
    alive.mkdir()
    other_host = tmp_path / ".pkg.tmp-otherhost-1-abc123"
    other_host.mkdir()
    old_unowned = tmp_path / ".pkg.tmp-abcd1234"                       # an older ncgen's name
    old_unowned.mkdir()
    os.utime(old_unowned, (time.time() - 2 * files.STALE_AGE,) * 2)
    mine = tmp_path / ".pkg.tmp-notes"                                  # the user's, not ours
    mine.write_text("keep")
    run(capsys, ["generate", str(EXAMPLES / "fourbar_planar.toml"), "-o", str(tmp_path / "pkg")], 0)
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == sorted(["pkg", alive.name, other_host.name, mine.name])


def test_partial_output_files_are_swept(tmp_path):
    host = files.temporary_name("x").split("-")[1]
    stale = tmp_path / f".traj.tmp-{host}-{_dead_pid()}-k2j3.npz"
    stale.write_bytes(b"half")
    with files.atomic_path(tmp_path / "traj.npz") as tmp:
        tmp.write_bytes(b"whole")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["traj.npz"]


#: Values put in place of each number of a model file, one at a time.
HOSTILE_VALUES = ["nan", "1" * 400, "1e300", '"1/0"', '"sqrt(-1)"', "true", "-1.0"]


@pytest.mark.slow      # ≈ 100 builds of one model file; fast:
#                       test_bad_models_are_one_clear_message_in_check_and_simulate, test_numbers_one_rule
def test_no_number_of_a_model_file_can_cause_an_internal_error(tmp_path, capsys):
    """The class test: every number of a shipped model file replaced by each hostile value
    gives exit 0 or 1 and a message, never a traceback or an internal error (exit 70)."""
    import re
    text = (EXAMPLES / "fourbar_planar.toml").read_text()
    numbers = list(re.finditer(r"(?<![\w.])-?\d+\.\d+(?:e-?\d+)?", text))
    assert len(numbers) >= 10
    path = tmp_path / "m.toml"
    for m in numbers:
        for value in HOSTILE_VALUES:
            path.write_text(text[:m.start()] + value + text[m.end():])
            code = main(["check", str(path)])
            out = capsys.readouterr()
            assert code in (0, 1) and "Traceback" not in out.err + out.out, (m.group(), value, out.err)
            assert code == 0 or out.err.strip() or "error" in out.out, (m.group(), value)


def test_problem_files_follow_the_same_encoding_rule(tmp_path):
    from ncgen.errors import ProblemFileError
    from ncgen.optim.problem_file import read_problem_file

    path = tmp_path / "p.toml"
    path.write_bytes(b'model = "m.toml"\n# caf\xe9\n')
    with pytest.raises(ProblemFileError, match=f"{path}: not UTF-8 text: byte 0xe9 at line 2"):
        read_problem_file(path)
    path.write_bytes(b'\xef\xbb\xbfmodel = "m.toml"\n')
    assert read_problem_file(path)[0] == {"model": "m.toml"}
