"""The viewer and the command line as a new user meets them (issue 35, classes 11 and 13):
an empty trajectory, a bad ``fps`` or colour, a misspelt member are named; a problem file
given to ``ncgen simulate``/``check`` says which command takes it; a missing extra (ffmpeg
for MP4, zarr and pyarrow for sweeps) is found before any run, naming the user's path; a
misspelt flag gets the flag meant; docs/sweeps.md's snippets are safe pasted into one script."""
from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

import ncgen as nc
from ncgen.cli import main
from ncgen.errors import NcgenError

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"


@pytest.fixture(scope="module")
def crank():
    model = nc.System.from_toml(EXAMPLES / "slider_crank.toml").build()
    return nc.simulate(model, 0.1, 0.01)


@pytest.mark.parametrize("kw, said", [
    ({"fps": float("nan")}, "to_html: fps: expected a finite number, got nan"),
    ({"fps": -30.0}, "to_html: fps: expected a positive number of frames per second, got -30"),
    ({"fps": 0}, "to_html: fps: expected a positive number of frames per second, got 0"),
    ({"fps": "fast"}, "to_html: fps: expected a number, got 'fast'"),
    ({"colors": {"crnk": "#ff0000"}}, r"colors: 'crnk' is not a member of 'slider_crank' \(did you mean 'crank'\?\)"),
    ({"colors": {"ground": "red"}}, "colors: 'ground' is not a member"),
    ({"colors": {"crank": 3}}, r"colors\['crank'\]: expected a CSS colour"),
    ({"colors": {"crank": ""}}, r"colors\['crank'\]: expected a CSS colour"),
    ({"colors": ["red"]}, r"colors: expected a dict \{member name: colour\}, got list"),
])
def test_to_html_checks_its_options(crank, tmp_path, kw, said):
    with pytest.raises(NcgenError, match=said):
        crank.to_html(tmp_path / "page.html", **kw)
    assert not (tmp_path / "page.html").exists()
    assert crank.to_html(tmp_path / "ok.html", fps=12.5, colors={"crank": "#ff0000"}).is_file()


@pytest.mark.parametrize("kw, said", [
    ({"title": 3}, "to_html: title: expected text or None, got int 3"),
    ({"mesh_paths": 3}, "to_html: mesh_paths: expected a folder or a list of folders, got int 3"),
    ({"mesh_paths": [None]}, r"to_html: mesh_paths\[0\]: expected a folder \(text or a path\), got NoneType"),
])
def test_to_html_checks_its_other_options(crank, tmp_path, kw, said):
    with pytest.raises(NcgenError, match=said):
        crank.to_html(tmp_path / "page.html", **kw)
    assert not (tmp_path / "page.html").exists()
    assert crank.to_html(tmp_path / "ok.html", mesh_paths=str(tmp_path), title="crank").is_file()   # one folder


@pytest.mark.parametrize("kw, said", [
    ({"max_frames": 0}, r"animate: max_frames: expected an integer >= 2 \(frames of the animation\), got 0"),
    ({"max_frames": 1.5}, r"animate: max_frames: expected an integer >= 2"),
    ({"max_frames": float("nan")}, r"animate: max_frames: expected an integer >= 2 .* got nan"),
    ({"size": -1.0}, r"animate: size: expected a positive number \(the figure's width in inches\), got -1.0"),
    ({"size": float("nan")}, "animate: size: expected a finite number, got nan"),
    ({"dpi": 0}, r"animate: dpi: expected a positive number \(dots per inch\), got 0"),
    ({"dpi": float("inf")}, "animate: dpi: expected a finite number, got inf"),
    ({"budget": -1.0}, r"animate: budget: expected a positive number \(seconds of drawing, or None\)"),
    ({"budget": float("nan")}, "animate: budget: expected a finite number, got nan"),
])
def test_animate_checks_its_options(crank, tmp_path, kw, said):
    """They ended in a ZeroDivisionError, matplotlib's ValueError, or were taken (a negative
    or NaN time budget)."""
    from ncgen.viz import animate
    with pytest.raises(NcgenError, match=said):
        animate(crank, tmp_path / "a.gif", **kw)
    assert not list(tmp_path.iterdir())


def test_viewers_refuse_an_empty_trajectory(crank, tmp_path):
    from ncgen.viz import animate
    empty = crank.head(0)
    assert len(empty.t) == 0
    with pytest.raises(NcgenError, match="to_html: .*empty.html: the trajectory is empty"):
        empty.to_html(tmp_path / "empty.html")
    with pytest.raises(NcgenError, match="animate: .*empty.gif: the trajectory is empty"):
        animate(empty, tmp_path / "empty.gif")
    with pytest.raises(NcgenError, match="animate: fps: expected a positive number"):
        animate(crank, tmp_path / "a.gif", fps=-1.0)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("command", ["simulate", "check"])
def test_a_problem_file_is_named_as_one(command, capsys):
    problem = str(EXAMPLES / "cartpole_swingup.toml")
    assert main([command, problem]) != 0
    err = capsys.readouterr().err
    assert "this is an optimal-control problem file (it names the model 'cartpole.toml'), not a model: use " \
           "`ncgen optimize` or `ncgen mpc`" in err and "unknown top-level key" not in err
    with pytest.raises(NcgenError, match="this is an optimal-control problem file"):
        nc.System.from_toml(EXAMPLES / "cartpole_swingup.toml")


@pytest.mark.parametrize("argv, said", [
    (["simulate", "M", "--tend", "1"], "unrecognized arguments: --tend 1 (did you mean '--t-end'?)"),
    (["simulate", "M", "--html=x.html", "--rtoll", "1e-6"], "unrecognized arguments: --rtoll 1e-6 (did you mean "
                                                            "'--rtol'?)"),
    (["sweep", "M", "--param", "omega=1", "--t-end", "1", "-o", "s.zarr", "--wokers", "2"],
     "(did you mean '--workers'?)"),
    (["--verison"], "unrecognized arguments: --verison (did you mean '--version'?)"),
])
def test_a_misspelt_flag_gets_the_one_meant(argv, said, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    argv = [str(EXAMPLES / "slider_crank.toml") if a == "M" else a for a in argv]
    assert main(argv) == 2
    assert said in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_missing_ffmpeg_is_found_before_the_run_naming_the_users_file(tmp_path, capsys, monkeypatch):
    from ncgen.viz import animation
    monkeypatch.setattr(animation.FFMpegWriter, "isAvailable", classmethod(lambda cls: False))
    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)
    monkeypatch.setattr("ncgen.runtime.simulate", lambda *a, **k: pytest.fail("simulated before the check"))
    movie = tmp_path / "run.mp4"
    assert main(["simulate", str(EXAMPLES / "slider_crank.toml"), "--t-end", "0.1", "--animate", str(movie)]) == 2
    err = capsys.readouterr().err
    assert f"--animate: animate: {movie}: writing MP4 needs ffmpeg" in err and ".tmp" not in err
    assert not list(tmp_path.iterdir())


def test_missing_sweep_extras_are_found_before_the_model_is_loaded(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "pyarrow", None)
    monkeypatch.setattr("ncgen.cli.sweep.load_model", lambda *a, **k: pytest.fail("loaded before the check"))
    out = tmp_path / "s.zarr"
    assert main(["sweep", str(EXAMPLES / "slider_crank.toml"), "--param", "omega=3,4", "--t-end", "0.1",
                 "-o", str(out)]) == 1
    assert f"sweep(path='{out}'): writing results needs zarr and pyarrow (pyarrow is missing)" in \
        capsys.readouterr().err
    assert not out.exists()


def test_sweeps_page_guards_every_snippet_that_runs_work():
    """Pasted into one script, docs/sweeps.md runs each run once: every Python snippet after
    the model is built is under ``if __name__ == "__main__":`` (spawned workers import the
    script again and run what is not)."""
    text = (ROOT / "docs" / "sweeps.md").read_text(encoding="utf-8")
    snippets = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(snippets) >= 6
    for code in snippets:
        top = [line for line in code.splitlines() if line and not line.startswith((" ", "#"))]
        work = [line for line in top if not line.startswith(("import ", "from ", "if __name__ == \"__main__\":"))
                and not line.startswith("model = nc.System.from_toml(")]
        assert not work, f"unguarded top-level work in docs/sweeps.md: {work}"


@pytest.mark.parametrize("command", ["optimize", "mpc"])
def test_a_model_file_given_for_a_problem_is_named_as_one(command, capsys, tmp_path):
    """The converse of a problem file given to ``ncgen simulate``: a model file given to
    ``ncgen optimize`` or ``ncgen mpc`` is said to be a model, with the file to give."""
    assert main([command, str(EXAMPLES / "cartpole.toml"), *(["-o", str(tmp_path / "m")] if command == "mpc" else [])]) == 1
    err = capsys.readouterr().err
    assert "cartpole.toml: this is a model file (it has a [system] or [[members]] table), not an optimal-control " \
           f"problem: `ncgen {command}` takes a problem file that names its model" in err
    assert "model: missing" not in err and not list(tmp_path.iterdir())
