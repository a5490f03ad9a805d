"""Trajectory: derived quantities, points and poses, summary, npz/csv files."""
import csv
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import NcgenError
from ncgen.runtime import Trajectory, simulate


@pytest.fixture(scope="module")
def model():
    """A bar hanging from the ground and a body hanging from the bar's free end."""
    s = nc.System("hang")
    bar = s.add_bar("bar", mass=1.0, ends=[s.ground.point((0, 0, 0)), (0.4, 0.0, -0.3)])
    bar.add_marker("mid", (0.0, 0, 0))
    box = s.add_body("box", mass=2.0, inertia=np.diag([0.02, 0.03, 0.04]), position=(0.5, 0.1, -0.5),
                     share={"r_i": bar.end(1)},
                     basis=[(-0.1, -0.1, 0.2), (1, 0, 0), (0, 1, 0), (0, 0, 1)])
    box.add_marker("corner", (0.1, 0.1, 0.1))
    return s.build()


@pytest.fixture(scope="module")
def traj(model):
    return simulate(model, 1.0, 0.02)


def test_shapes_and_names(model, traj):
    n = len(traj)
    assert n == 51 and traj.q.shape == (n, model.nq) and traj.v.shape == (n, model.nq)
    assert traj.lam.shape == (n, model.nc) and traj.u.shape == (n, 0) and traj.p.shape == (0,)
    assert traj.markers.shape == (n, 2, 3) and traj.dim == 3
    assert traj.coordinate_names == model.coordinate_names
    assert traj.marker_names == ["bar.mid", "box.corner"] and traj.member_names == ["bar", "box"]
    for key in ("kinetic", "potential", "energy", "constraint_residual", "velocity_residual"):
        assert getattr(traj, key).shape == (n,)


def test_points_markers_and_poses_agree(model, traj):
    """Marker = point(member, local) = p + R local, and the shared point stays shared."""
    np.testing.assert_allclose(traj.marker("box.corner"), traj.point("box", (0.1, 0.1, 0.1)), atol=1e-12)
    R, p = traj.poses()
    assert R.shape == (len(traj), 2, 3, 3) and p.shape == (len(traj), 2, 3)
    i = traj.member_names.index("box")
    corner = np.einsum("nij,j->ni", R[:, i], [0.1, 0.1, 0.1]) + p[:, i]
    np.testing.assert_allclose(corner, traj.marker("box.corner"), atol=1e-9)
    RtR = np.einsum("nij,nik->njk", R[:, i], R[:, i])
    np.testing.assert_allclose(RtR, np.broadcast_to(np.eye(3), RtR.shape), atol=1e-7)
    L = 0.5
    end = traj.point("bar", (L / 2, 0, 0))
    np.testing.assert_allclose(end, traj.point("box", (-0.1, -0.1, 0.2)), atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(end, axis=1), L, atol=1e-7)
    np.testing.assert_allclose(traj.marker("bar.mid"), end / 2, atol=1e-12)


def test_energy_is_kinetic_plus_potential(model, traj):
    for k in (0, 17, len(traj) - 1):
        T, V = model.energy(traj.q[k], traj.v[k])
        assert traj.kinetic[k] == pytest.approx(T, rel=1e-12)
        assert traj.potential[k] == pytest.approx(V, rel=1e-12)
    assert traj.energy_drift < 1e-4 * traj.energy_scale


def test_unknown_names(traj):
    with pytest.raises(NcgenError, match="no marker named 'box.nope'"):
        traj.marker("box.nope")
    with pytest.raises(nc.ModelError, match="no member named 'crate'"):
        traj.point("crate", (0, 0, 0))


def test_summary(traj):
    text = traj.summary()
    assert text.startswith("Trajectory of model 'hang': 51 steps, t = 0 ... 1 s")
    assert "idas (vm backend, rtol 1e-08, atol 1e-1" in text and "max |E - E(t0)|" in text
    assert "INCOMPLETE" not in text and repr(traj) == "<Trajectory 'hang': 51 steps, t = 0 ... 1 s>"


def test_npz_round_trip(tmp_path, model, traj):
    path = traj.save(tmp_path / "sub" / "run.npz")
    assert path.is_file() and [p.name for p in path.parent.iterdir()] == ["run.npz"]
    back = Trajectory.load(path)
    for key in ("t", "q", "v", "lam", "u", "p", "kinetic", "potential", "constraint_residual",
                "velocity_residual", "markers"):
        np.testing.assert_array_equal(getattr(back, key), getattr(traj, key))
    assert back.coordinate_names == traj.coordinate_names and back.constraint_names == traj.constraint_names
    assert back.model_name == "hang" and back.info == traj.info and back.complete
    np.testing.assert_array_equal(back.marker("box.corner"), traj.marker("box.corner"))
    with pytest.raises(NcgenError, match="loaded without it"):
        back.point("box", (0, 0, 0))
    with_model = Trajectory.load(path, model=model)
    np.testing.assert_array_equal(with_model.point("box", (0, 0, 0)), traj.point("box", (0, 0, 0)))


def test_load_checks_the_model_and_the_file(tmp_path, traj):
    path = traj.save(tmp_path / "run.npz")
    other = nc.System("other")
    other.add_point("pt", mass=1.0, position=(0, 0, 0))
    with pytest.raises(NcgenError, match="model 'hang'"):
        Trajectory.load(path, model=other.build())
    np.savez(tmp_path / "foreign.npz", x=np.zeros(3))
    with pytest.raises(NcgenError, match="not a trajectory saved by ncgen"):
        Trajectory.load(tmp_path / "foreign.npz")
    with pytest.raises(NcgenError, match="cannot read"):
        Trajectory.load(tmp_path / "missing.npz")


def test_csv(tmp_path, traj):
    path = traj.save(tmp_path / "run.csv")
    with open(path) as fh:
        rows = list(csv.reader(fh))
    nq = traj.q.shape[1]
    assert rows[0][0] == "t [s]" and [h.split(" [")[0] for h in rows[0][1:1 + nq]] == traj.coordinate_names
    assert rows[0][-5:] == ["energy [J]", "kinetic [J]", "potential [J]", "constraint_residual [m^2]",
                            "velocity_residual [m^2/s]"]
    table = np.array(rows[1:], dtype=float)
    assert table.shape == (len(traj), len(rows[0]))
    np.testing.assert_array_equal(table[:, 0], traj.t)
    np.testing.assert_array_equal(table[:, 1:1 + nq], traj.q)
    np.testing.assert_array_equal(table[:, 1 + nq:1 + 2 * nq], traj.v)
    np.testing.assert_array_equal(table[:, -1], traj.velocity_residual)


def test_save_rejects_other_formats_and_leaves_nothing(tmp_path, traj, monkeypatch):
    with pytest.raises(NcgenError, match=".npz or .csv"):
        traj.save(tmp_path / "run.mat")
    monkeypatch.setattr(Trajectory, "_write_npz", lambda self, fh: (fh.write(b"partial"), 1 / 0))
    (tmp_path / "old.npz").write_bytes(b"previous")
    with pytest.raises(ZeroDivisionError):
        traj.save(tmp_path / "old.npz")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.npz"]
    assert (tmp_path / "old.npz").read_bytes() == b"previous"


def test_derived_outputs_are_computed_on_first_access_and_equal_the_eager_ones():
    """A joint-space run returns before its natural coordinates, multipliers, energies and
    residuals are evaluated; read, they equal the model's functions at the states, the
    energy is conserved (a passive pendulum) and a pickle carries them computed."""
    import pickle

    from ncgen.runtime import outputs

    model = nc.System.from_toml(Path(__file__).resolve().parents[1] / "examples" / "double_pendulum.toml").build()
    traj = simulate(model, 1.0, 0.01, method="joint", rtol=1e-10, atol=1e-12)
    lazy = ("q", "v", "lam", "kinetic", "potential", "constraint_residual", "markers")
    assert not any(isinstance(traj._arrays.get(key), np.ndarray) for key in lazy)     # none computed yet
    copy = pickle.loads(pickle.dumps(traj))
    assert not any(callable(value) for value in copy._arrays.values())
    T, V = outputs.energies(model, traj.t, traj.q, traj.v, model.p0)
    assert np.array_equal(traj.kinetic, T) and np.array_equal(traj.potential, V)
    assert np.array_equal(copy.q, traj.q) and np.array_equal(copy.lam, traj.lam)
    assert traj.energy_drift < 1e-7 * traj.energy_scale and np.max(traj.constraint_residual) < 1e-9
    lam = np.array(model.functions["accel"](traj.t[5], traj.q[5], traj.v[5], traj.u[5], model.p0)[1]).reshape(-1)
    assert np.allclose(traj.lam[5], lam, rtol=1e-9, atol=1e-9)
