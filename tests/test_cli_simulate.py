"""``ncgen simulate``: trajectory files, plot, parameters; bad input gives one clear
message, a non-zero exit status and no output file."""
from pathlib import Path

import numpy as np
import pytest

from ncgen.cli import main
from ncgen.runtime import Trajectory

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"

BLOWUP = """
[system]
name = "blowup"

[[members]]
name = "ball"
kind = "point"
mass = 1.0
position = [0.0, 0.0, 0.0]

[[forces]]
type = "PointForce"
member = "ball"
at = [0.0, 0.0, 0.0]
force = [0.0, 0.0, "1/(0.5 - t)**3"]     # infinite at t = 0.5 s
"""


@pytest.fixture(autouse=True)
def private_cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "ncgen-cache"))


def run(capsys, argv, status=0):
    assert main(argv) == status
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    return captured


def test_npz_csv_and_plot(tmp_path, capsys):
    out = run(capsys, ["simulate", str(EXAMPLES / "chain.toml"), "--t-end", "0.5", "--dt", "0.05",
                       "-o", str(tmp_path / "c.npz"), "--plot", str(tmp_path / "c.png"), "--backend", "vm"]).out
    assert "Trajectory of model 'chain': 11 steps" in out
    traj = Trajectory.load(tmp_path / "c.npz")
    assert np.allclose(traj.t, np.linspace(0, 0.5, 11)) and traj.q.shape == (11, 15)
    assert (tmp_path / "c.png").read_bytes()[:4] == b"\x89PNG"
    run(capsys, ["simulate", str(EXAMPLES / "chain.toml"), "--t-end", "0.1", "-o", str(tmp_path / "c.csv"),
                 "--backend", "vm"])
    header = (tmp_path / "c.csv").read_text().splitlines()[0].split(",")
    assert header[:2] == ["t [s]", "bar1.r_j.x [m]"] and "energy [J]" in header and "v.bar1.r_j.x [m/s]" in header
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.csv", "c.npz", "c.png"]


def test_parameter_override(tmp_path, capsys):
    for omega, name in ((6.283185307179586, "a.npz"), (12.566370614359172, "b.npz")):
        run(capsys, ["simulate", str(EXAMPLES / "slider_crank.toml"), "--t-end", "0.25", "--dt", "0.25",
                     "-o", str(tmp_path / name), "--param", f"omega={omega}", "--backend", "vm"])
    a, b = Trajectory.load(tmp_path / "a.npz"), Trajectory.load(tmp_path / "b.npz")
    x = a.coordinate_names.index("slider.r_i.x")
    # a quarter turn at one turn per second, half a turn at two
    assert np.isclose(a.q[-1, x], 0.1 * np.cos(np.pi / 2) + np.sqrt(0.09 - 0.01), atol=1e-6)
    assert np.isclose(b.q[-1, x], 0.2, atol=1e-6)
    assert np.isclose(b.p[0], 12.566370614359172)


@pytest.mark.parametrize("argv,expected", [
    (["--param", "omeg=3"], "has no parameter 'omeg' (parameters: omega)"),
    (["--param", "omega"], "expected NAME=VALUE"),
    (["--param", "omega=1,2"], "expected 1 finite number(s)"),
    (["--method", "rk4"], "method: expected one of"),
    (["--dt", "-1"], "dt: expected a positive"),
])
def test_bad_options_are_errors(tmp_path, capsys, argv, expected):
    err = run(capsys, ["simulate", str(EXAMPLES / "slider_crank.toml"), "--t-end", "0.1",
                       "-o", str(tmp_path / "x.npz"), "--backend", "vm", *argv], status=1).err
    assert expected in err and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv,expected", [
    (["-o", "x.txt"], "expected a file name ending in .npz or .csv"),
    (["-o", "x.npz", "--plot", "p.gif"], "--plot 'p.gif': expected a file name ending in .png"),
    (["-o", "no/such/dir/x.npz"], "does not exist"),
    (["-o", "x.npz", "--backend", "gpu"], "invalid choice: 'gpu'"),
])
def test_usage_errors_exit_2(tmp_path, capsys, monkeypatch, argv, expected):
    monkeypatch.chdir(tmp_path)
    err = run(capsys, ["simulate", str(EXAMPLES / "chain.toml"), "--t-end", "0.1", *argv], status=2).err
    assert expected in err
    assert list(tmp_path.iterdir()) == []


def test_unknown_and_invalid_model_files(tmp_path, capsys):
    err = run(capsys, ["simulate", str(tmp_path / "nope.toml"), "--t-end", "1", "-o", str(tmp_path / "x.npz")],
              status=1).err
    assert "model file" in err and "does not exist" in err
    bad = tmp_path / "bad.toml"
    bad.write_text("[system]\nname = 'x'\n[[members]]\nname = 'b'\nkind = 'bar'\nmass = -1.0\n"
                   "ends = [[0, 0, 0], [1, 0, 0]]\n")
    err = run(capsys, ["simulate", str(bad), "--t-end", "1", "-o", str(tmp_path / "x.npz")], status=1).err
    assert err.startswith(f"ncgen simulate: error: {bad}: members[0]: mass: expected a positive number")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]


def test_inconsistent_initial_state(tmp_path, capsys):
    text = (EXAMPLES / "chain.toml").read_text().replace(
        'ends = [{ ground = [0.0, 0.0, 0.0] }, [0.3, 0.0, 0.0]]',
        'ends = [{ ground = [0.0, 0.0, 0.0] }, [0.3, 0.0, 0.0]]\nvelocity = [1.0, 0.0, 0.0]')
    (tmp_path / "m.toml").write_text(text)
    err = run(capsys, ["simulate", str(tmp_path / "m.toml"), "--t-end", "1", "-o", str(tmp_path / "x.npz")],
              status=1).err
    assert "cannot be built" in err and "inconsistent initial velocity" in err
    assert [p.name for p in tmp_path.iterdir()] == ["m.toml"]


def test_failing_integration_writes_the_partial_trajectory(tmp_path, capsys):
    (tmp_path / "blowup.toml").write_text(BLOWUP)
    err = run(capsys, ["simulate", str(tmp_path / "blowup.toml"), "--t-end", "1", "-o", str(tmp_path / "x.npz"),
                       "--plot", str(tmp_path / "x.png"), "--backend", "vm"], status=1).err
    assert err.startswith("ncgen simulate: error: simulation of 'blowup' failed between t = 0.49 s")
    partial = tmp_path / "x.incomplete.npz"
    assert err.rstrip().endswith(f"(t = 0 ... 0.49 s, marked incomplete) was written to {partial}")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["blowup.toml", "x.incomplete.npz"]
    traj = Trajectory.load(partial)
    assert not traj.complete and traj.t[-1] == pytest.approx(0.49) and len(traj) == 50
    t = traj.t                  # z'' = (0.5 − t)⁻³ − g from rest: z = 1/(2(0.5 − t)) − 1 − 2t − g t²/2
    exact = 1 / (2 * (0.5 - t)) - 1 - 2 * t - 9.81 * t**2 / 2
    np.testing.assert_allclose(traj.q[:, 2], exact, rtol=1e-5, atol=1e-9)


def test_help_has_examples(capsys):
    assert main(["simulate", "--help"]) == 0
    out = capsys.readouterr().out
    assert "examples:" in out and "--param omega=20" in out and "--method" in out


def test_animation(tmp_path, capsys):
    run(capsys, ["simulate", str(EXAMPLES / "fourbar_planar.toml"), "--t-end", "0.1", "--dt", "0.02",
                 "-o", str(tmp_path / "f.npz"), "--animate", str(tmp_path / "f.gif"), "--backend", "vm"])
    assert (tmp_path / "f.gif").read_bytes()[:6] in (b"GIF89a", b"GIF87a")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.gif", "f.npz"]
