"""Output paths that cannot be written are refused by every subcommand before any work
(issue 24, class 6): a directory that does not exist, a path that is a directory (or, for
a directory output, a file), a directory that takes no new file.  The message names the
path as given (never a temporary file), the exit status is 2 (usage), nothing is written.

The commands run for real, through the ``ncgen`` command's ``main``, in one subprocess (one
interpreter start for every case; each case in its own directory, its exit status what ``python
-m ncgen.cli`` would exit with).  "Before any work" is shown by giving a model file that does not
exist: a command that loaded it first would complain about the model."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from argparse import Namespace
from pathlib import Path

import pytest

from ncgen.cli.common import check_files, directory_problem, file_problem
from ncgen.errors import NcgenError
from ncgen.files import atomic_path

ROOT = Path(__file__).resolve().parents[1]


def read_only_directory(base: Path):
    """A directory in which no file can be created (a chmod 555 directory ``base/ro``; as root,
    which ignores the mode, /sys when it refuses new files), yielded (a generator fixture's body)."""
    d = base / "ro"
    d.mkdir()
    d.chmod(0o555)
    candidates = [d, Path("/sys")]
    for c in candidates:
        try:
            with tempfile.TemporaryFile(dir=c):
                pass
        except OSError:
            yield c
            break
    else:
        pytest.skip("no directory refuses new files here")
    d.chmod(0o755)


@pytest.fixture
def read_only(tmp_path):
    yield from read_only_directory(tmp_path)


#: Runs ``ncgen`` for each ``[directory, arguments]`` of ``argv[1]`` (JSON) as ``python -m
#: ncgen.cli`` would (exit status: ``main``'s return or its ``SystemExit``'s code); prints the
#: JSON list of ``[status, standard error, seconds]``.
RUN_EACH = """
import contextlib, io, json, os, sys, time, traceback
from ncgen.cli import main
done = []
for cwd, args in json.loads(sys.argv[1]):
    os.chdir(cwd)
    err, t0 = io.StringIO(), time.perf_counter()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            status = main(args)
        except SystemExit as e:
            status = e.code
        except BaseException:
            traceback.print_exc()
            status = 1
    done.append([status, err.getvalue(), time.perf_counter() - t0])
print(json.dumps(done))
"""


def ncgen_each(runs: list[tuple[Path, list[str]]]) -> list[tuple[int, str, float]]:
    """``(exit status, standard error, seconds)`` of ``ncgen args`` run in ``directory`` for
    each ``(directory, args)`` of ``runs``, in one subprocess (:data:`RUN_EACH`)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, "-c", RUN_EACH, json.dumps([[str(d), a] for d, a in runs])], cwd=ROOT,
                       env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    return [tuple(x) for x in json.loads(r.stdout.splitlines()[-1])]


#: (subcommand arguments with {bad} for the unwritable path, the option, which kind of bad path)
CASES = {
    "simulate -o, missing directory": (["simulate", "missing.toml", "-o", "{bad}"], "-o/--output", "missing", "x.npz"),
    "simulate --plot, a directory": (["simulate", "missing.toml", "--plot", "{bad}"], "--plot", "is_dir", "p.png"),
    "simulate --html, read-only": (["simulate", "missing.toml", "--html", "{bad}"], "--html", "read_only", "h.html"),
    "derive -o, a directory": (["derive", "ruvw", "-o", "{bad}"], "-o/--output", "is_dir", "d.tex"),
    "generate -o, a file": (["generate", "missing.toml", "-o", "{bad}"], "-o/--output", "is_file", "pkg"),
    "generate -o, read-only": (["generate", "missing.toml", "-o", "{bad}"], "-o/--output", "read_only", "pkg"),
    "equilibrium -o, read-only": (["equilibrium", "missing.toml", "-o", "{bad}"], "-o/--output", "read_only", "e.csv"),
    "modes --animate, missing directory": (["modes", "missing.toml", "--animate", "{bad}"], "--animate", "missing",
                                           "m.gif"),
    "optimize -o, a directory": (["optimize", "missing.toml", "-o", "{bad}"], "-o/--output", "is_dir", "s.npz"),
    "sweep -o, read-only": (["sweep", "missing.toml", "--param", "k=1:2", "--t-end", "1", "-o", "{bad}"],
                            "-o/--output", "read_only", "s.zarr"),
    "mpc -o, a file": (["mpc", "missing.toml", "-o", "{bad}"], "-o/--output", "is_file", "mpc"),
    "demo -o, under a file": (["demo", "-o", "{bad}"], "-o/--output", "under_file", "demo"),
}


def bad_path(kind: str, name: str, tmp_path: Path, read_only: Path) -> tuple[str, str]:
    """The path and what the message says about it."""
    if kind == "missing":
        return f"no_such_dir/{name}", "directory 'no_such_dir' does not exist"
    if kind == "is_dir":
        (tmp_path / name).mkdir()
        return name, "is a directory"
    if kind == "is_file":
        (tmp_path / name).write_text("mine")
        return name, "exists and is not a directory"
    if kind == "under_file":
        (tmp_path / "notes.txt").write_text("mine")
        return f"notes.txt/{name}", "notes.txt' is not a directory"
    return str(read_only / name), "is not writable"


@pytest.fixture(scope="module")
def refusals(tmp_path_factory):
    """``{case: (path, what the message says, files before, exit status, standard error,
    seconds, files after)}`` of every case of :data:`CASES`, each run in its own directory."""
    ro = read_only_directory(tmp_path_factory.mktemp("read_only"))
    read_only = next(ro)
    prepared = {}
    for case, (args, _, kind, name) in CASES.items():
        d = tmp_path_factory.mktemp("case")
        path, says = bad_path(kind, name, d, read_only)
        prepared[case] = d, path, says, sorted(p.name for p in d.rglob("*"))
    ran = ncgen_each([(d, [a.replace("{bad}", path) for a in CASES[case][0]])
                      for case, (d, path, _, _) in prepared.items()])
    yield {case: (path, says, before, *r, sorted(p.name for p in d.rglob("*")))
           for (case, (d, path, says, before)), r in zip(prepared.items(), ran)}
    next(ro, None)


@pytest.mark.parametrize("case", list(CASES))
def test_every_subcommand_refuses_an_unwritable_output_before_working(case, refusals):
    option = CASES[case][1]
    path, says, before, status, stderr, seconds, after = refusals[case]
    assert status == 2, stderr
    assert f"error: {option} {path!r}: " in stderr and says in stderr, stderr
    assert "missing.toml" not in stderr.split("error:")[-1]          # refused before the model is read
    assert ".tmp" not in stderr and "Traceback" not in stderr
    assert after == before                                           # nothing written
    # wall: the refusal comes before any build (the command's imports, < 1 s unloaded, ~4 s at load 8
    # on 2 cores) while the demo it would run takes minutes; 60 s separates the two at any load
    assert seconds < 60


def test_helper_rules(tmp_path, read_only):
    """The shared rules (ncgen.cli.common), for files and directory outputs."""
    (tmp_path / "d.csv").mkdir()
    (tmp_path / "f").write_text("x")
    assert file_problem(str(tmp_path / "new.csv")) is None
    assert file_problem(str(tmp_path / "f")) is None                   # replaced atomically
    assert "is a directory" in file_problem(str(tmp_path / "d.csv"))
    assert "does not exist" in file_problem(str(tmp_path / "a" / "b.csv"))
    assert "is not a directory" in file_problem(str(tmp_path / "f" / "b.csv"))
    assert "is not writable" in file_problem(str(read_only / "x.csv"))
    assert directory_problem(str(tmp_path / "a" / "b" / "pkg")) is None    # parents are made
    assert directory_problem(str(tmp_path / "d.csv")) is None              # an existing directory
    assert "exists and is not a directory" in directory_problem(str(tmp_path / "f"))
    assert "is not a directory" in directory_problem(str(tmp_path / "f" / "pkg"))
    assert "is not writable" in directory_problem(str(read_only / "pkg"))

    class Parser:
        def error(self, message):
            raise SystemExit(message)

    with pytest.raises(SystemExit, match=r"-o/--output '.*x\.txt': directory '.*ro' is not writable|"
                                         r"-o/--output '/sys/x\.txt'"):
        check_files(Namespace(output=str(read_only / "x.txt")), Parser(), ())
    check_files(Namespace(output=str(tmp_path / "any.suffix")), Parser(), ())   # () takes any suffix


def test_atomic_writes_name_the_users_path(tmp_path, read_only):
    """When the directory goes away or refuses files after the checks, the error names the
    path given, not the temporary sibling."""
    with pytest.raises(NcgenError, match=r"cannot write '.*x\.csv': .*\(directory"):
        with atomic_path(read_only / "x.csv") as tmp:
            tmp.write_text("never")
    (tmp_path / "d.csv").mkdir()
    with pytest.raises(NcgenError, match=r"cannot write '.*d\.csv': it is a directory"):
        with atomic_path(tmp_path / "d.csv") as tmp:
            tmp.write_text("never")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.csv", "ro"]
