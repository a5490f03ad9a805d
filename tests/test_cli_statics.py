"""``ncgen equilibrium`` and ``ncgen modes`` on the shipped examples: tables, files, plots,
bad input; the double pendulum's frequencies against its minimal-coordinate solution."""
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

from ncgen.cli import main

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def run(capsys, argv, status=0):
    assert main(argv) == status
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    return captured


def double_pendulum_frequencies():
    """examples/double_pendulum.toml: two 1 kg links, 0.5 m, centre of mass at mid-length,
    I = 0.0213 kg m² about the hinge-parallel axis through it; hinges along y."""
    m, l, c, I, g = 1.0, 0.5, 0.25, 0.0213, 9.81
    M = np.array([[I + m * c**2 + m * l**2, m * l * c], [m * l * c, I + m * c**2]])
    K = np.diag([(m * c + m * l) * g, m * c * g])
    return np.sqrt(scipy.linalg.eigh(K, M, eigvals_only=True)) / (2 * np.pi)


def test_equilibrium_table_and_files(capsys, tmp_path):
    out = run(capsys, ["equilibrium", str(EXAMPLES / "double_pendulum.toml"), "-o", str(tmp_path / "eq.csv"),
                       "--plot", str(tmp_path / "eq.png"), "--no-share"]).out      # every joint's reaction
    assert "stability: stable" in out and "shoulder" in out
    rows = dict(line.split(",") for line in (tmp_path / "eq.csv").read_text().splitlines()[1:])
    assert float(rows["q:link1.r_i.z"]) == pytest.approx(-0.25, abs=1e-9)   # hanging straight down
    assert (tmp_path / "eq.png").stat().st_size > 1000


def test_equilibrium_npz(capsys, tmp_path):
    run(capsys, ["equilibrium", str(EXAMPLES / "double_pendulum.toml"), "-o", str(tmp_path / "eq.npz"),
                 "--no-share"])
    data = np.load(tmp_path / "eq.npz")
    names = list(data["coordinate_names"])
    assert data["q"][names.index("link1.r_i.z")] == pytest.approx(-0.25, abs=1e-9)
    assert data["lam"].shape == data["constraint_names"].shape
    assert np.all(np.linalg.eigvalsh(data["K_reduced"] + data["K_reduced"].T) > 0)   # hanging: stable


def test_modes_table_and_csv(capsys, tmp_path):
    out = run(capsys, ["modes", str(EXAMPLES / "double_pendulum.toml"), "-o", str(tmp_path / "m.csv"),
                       "--plot", str(tmp_path / "m.png")]).out
    assert "vibration" in out
    data = np.genfromtxt(tmp_path / "m.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    np.testing.assert_allclose(data["frequency_hz"], double_pendulum_frequencies(), rtol=1e-8)
    assert (tmp_path / "m.png").stat().st_size > 1000


def test_cable_tensions_printed(capsys):
    out = run(capsys, ["equilibrium", str(EXAMPLES / "tensegrity.toml"), "--param", "tension=5"]).out
    assert "vertical1" in out and "taut" in out and "stability: neutral" in out


def test_bad_input(capsys, tmp_path):
    err = run(capsys, ["equilibrium", str(EXAMPLES / "cartpole.toml"), "--input", "shove=1"], status=1).err
    assert "--input 'shove=1'" in err and "push" in err
    err = run(capsys, ["modes", str(EXAMPLES / "cartpole.toml"), "-o", str(tmp_path / "m.txt")], status=2).err
    assert "expected a file name ending in .csv or .npz" in err


def test_mode_animation(tmp_path):
    import ncgen as nc
    model = nc.System.from_toml(EXAMPLES / "cartpole.toml").build()
    modes = nc.modes(model)
    k = modes.kind.index("vibration")
    from ncgen.viz.statics_pictures import animate_mode
    path = animate_mode(modes, k, tmp_path / "mode.gif", cycles=1, frames_per_cycle=4)
    assert Path(path).stat().st_size > 1000
    traj = modes.trajectory(k, cycles=1, frames_per_cycle=4)
    assert traj.constraint_residual.max() < 1e-10          # frames stay on the constraints
    np.testing.assert_allclose(traj.q[0], modes.equilibrium.q, atol=1e-12)


def test_equilibrium_reports_joints_eliminated_by_sharing(capsys):
    """Default build (sharing): the hinges of the hanging double pendulum are shared
    coordinates, and the table still gives their reactions: the shoulder carries both 1 kg
    links, the elbow one."""
    out = run(capsys, ["equilibrium", str(EXAMPLES / "double_pendulum.toml")]).out
    rows = [line.split() for line in out.splitlines() if line.startswith(("shoulder ", "elbow "))]
    table = {(r[0], r[1]): [float(x) for x in r[2:5]] for r in rows}
    np.testing.assert_allclose(table[("shoulder", "link1")], [0, 0, 2 * 9.81], atol=1e-9)
    np.testing.assert_allclose(table[("elbow", "link2")], [0, 0, 9.81], atol=1e-9)
