"""Progress bars (tqdm): shown when asked or on a terminal, never in captured output."""
import ncgen as nc
from ncgen.progress import Ticker, bar, enabled


def pendulum():
    s = nc.System("progress_pendulum", gravity=(0, -9.81))
    s.add_bar("bar", mass=1.0, ends=[s.ground.point((0, 0)), (1.0, 0.0)])
    return s.build()


def test_simulation_bar_when_asked_and_silent_otherwise(capsys):
    model = pendulum()
    nc.simulate(model, 1.0, 0.01, progress=True)
    assert "simulating progress_pendulum" in capsys.readouterr().err
    nc.simulate(model, 1.0, 0.01)                     # stderr is not a terminal here
    assert capsys.readouterr().err == ""


def test_switches(monkeypatch, capsys):
    assert not enabled(None) and enabled(True) and not enabled(False)
    monkeypatch.setenv("NCGEN_PROGRESS", "0")
    assert not enabled(True)
    monkeypatch.delenv("NCGEN_PROGRESS")
    with bar(3, "work", mode=True) as b:
        b.update(3)
    with Ticker("a long C call", mode=True):
        pass
    err = capsys.readouterr().err
    assert "work" in err and "a long C call" in err
