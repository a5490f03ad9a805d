"""The generated C of every shipped example builds with ``-Wall -Wextra -Werror -pedantic``,
and its programs run clean under AddressSanitizer and UndefinedBehaviorSanitizer, with the
default arguments and with hostile ones (issue 13, class 6).

The packages are generated afresh from ``examples/*.toml`` (the same files as the committed
``generated/``, which ``test_generated_up_to_date`` holds equal to a fresh generation), so
this test checks the templates of this checkout even before ``generated/`` is regenerated.
Every source is compiled at ``-O0`` (fast to build; the sanitizers check the same code at
any level) with ``-fno-sanitize-recover=all``, so any report is a non-zero exit.  The
CasADi kernel files (straight-line arithmetic, most of the build time) get AddressSanitizer
only: it catches what matters there, a work array sized wrongly by the calling program;
UndefinedBehaviorSanitizer instruments the programs, the stepper loop and the metadata.  Each
program must then answer: 0 for valid arguments, 2 with a message naming the argument for
bad ones — never a crash or a sanitizer report.  Leak detection is off: LeakSanitizer does
not run under ptrace, as in many CI containers.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import tomllib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from test_generated_up_to_date import EXAMPLES, regenerate

CC = os.environ.get("CC") or shutil.which("gcc") or shutil.which("clang") or shutil.which("cc")
pytestmark = [pytest.mark.slow, pytest.mark.timeout(1800),   # every shipped package built under the sanitizers
              pytest.mark.skipif(CC is None, reason="no C compiler (gcc, clang or cc) on PATH: "
                                                    "the generated C cannot be built")]
WARNINGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]
SANITIZE = ["-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer"]
KERNEL_SANITIZE = ["-fsanitize=address", "-fno-omit-frame-pointer"]
ENV = {**os.environ, "ASAN_OPTIONS": "detect_leaks=0:abort_on_error=0",
       "UBSAN_OPTIONS": "print_stacktrace=1:halt_on_error=1"}
#: Hostile arguments of <model>_simulate [t_end [h]] and the argument the message must name.
BAD_SIMULATE = [
    (["1e20", "1e-3"], "h"), (["inf"], "t_end"), (["nan"], "t_end"), (["-1"], "t_end"),
    (["0"], "t_end"), (["abc"], "t_end"), ([""], "t_end"), (["1e999"], "t_end"), (["2x"], "t_end"),
    (["0.05", "1e-320"], "h"), (["1", "0"], "h"), (["1", "-0.1"], "h"), (["1", "1e-12"], "h"),
    (["1", "0.1", "3"], "at most 2 arguments"),
]


def _run(cmd, cwd, timeout=120):
    return subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, env=ENV, timeout=timeout)


def _sanitizers_work(tmp: Path) -> bool:
    (tmp / "probe.c").write_text("int main(void) { return 0; }\n")
    out = _run([CC, *SANITIZE, "probe.c", "-o", "probe"], tmp)
    return out.returncode == 0 and _run(["./probe"], tmp).returncode == 0


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> dict[str, tuple[Path, dict]]:
    """Every example's package, compiled: model name -> (directory, manifest)."""
    root = tmp_path_factory.mktemp("sanitized")
    if not _sanitizers_work(root):
        pytest.skip(f"{CC} cannot build and run -fsanitize=address,undefined programs here "
                    "(libasan/libubsan missing)")
    regenerate(root)
    packages = {p.name: (p, json.loads((p / "manifest.json").read_text()))
                for p in sorted(root.iterdir()) if (p / "manifest.json").is_file()}
    jobs = [(d, src) for d, m in packages.values()
            for src in m["build"]["sources"] + [m["build"]["main"], *m["build"].get("programs", [])]]

    def compile_one(job):
        d, src = job
        flags = KERNEL_SANITIZE if "_kernels_" in src else SANITIZE
        return src, _run([CC, *WARNINGS, "-O0", *flags, "-I.", "-c", src, "-o", src[:-2] + ".o"], d, 600)

    with ThreadPoolExecutor(max_workers=2) as pool:
        for src, out in pool.map(compile_one, jobs):
            assert out.returncode == 0, f"{src} does not compile cleanly:\n{out.stderr[-3000:]}"
    for d, m in packages.values():
        objs = [s[:-2] + ".o" for s in m["build"]["sources"]]
        for prog, main in [(m["build"]["executable"], m["build"]["main"])] + \
                          [(p[:-2], p) for p in m["build"].get("programs", [])]:
            out = _run([CC, *SANITIZE, "-o", prog, main[:-2] + ".o", *objs, "-lm"], d)
            assert out.returncode == 0, out.stderr[-2000:]
    return packages


def _clean(out) -> None:
    text = out.stderr + out.stdout
    assert "runtime error" not in text and "AddressSanitizer" not in text and out.returncode >= 0, text[-3000:]


def test_every_example_is_shipped(built):
    names = set(built)
    assert {"chain", "fourbar_planar", "heavy_top", "tensegrity", "falling_chain", "boxes", "box_stack"} <= names


def test_contact_scene_lands_clean(built):
    """The contact scene (``examples/falling_chain.toml``, built with nonsmooth contacts: the
    contact half of the stepper, ``ncgen_contact.h``) run through its landing at 0.32 s, so
    that impacts with friction and restitution, contacts at rest and the push-out all run
    under the sanitizers: the chain's four nodes end on the floor (z = the radius of their
    spheres), none through it."""
    d, m = built["falling_chain"]
    radius = tomllib.loads((EXAMPLES / "falling_chain.toml").read_text())["contacts"][0]["radius"]
    assert "ncgen_contact.h" in m["build"]["headers"]
    out = _run(["./falling_chain_simulate", "0.6"], d)
    _clean(out)
    assert out.returncode == 0, out.stderr
    values = dict(line.split(" = ") for line in out.stdout.splitlines())
    z = [float(values[f"q[{3 * k + 2}]"]) for k in range(4)]            # nodes r_i, r_j of bar1, bar2, bar3
    assert min(z) > radius - 1e-6 and max(z) < radius + 1e-3, z


def test_box_stack_lands_clean(built):
    """``examples/box_stack.toml`` (boxes on boxes: ``BoxBox`` corners, the ball's ``SphereBox``)
    run past the boxes' landing under the sanitizers: the crate rests on the table (its
    centre at 0.45 m) and the small box on the crate (0.54 m)."""
    d, _ = built["box_stack"]
    out = _run(["./box_stack_simulate", "0.3"], d)
    _clean(out)
    assert out.returncode == 0, out.stderr
    values = dict(line.split(" = ") for line in out.stdout.splitlines())
    z_crate, z_top = float(values["q[2]"]), float(values["q[14]"])       # r_i of crate, of top
    assert abs(z_crate - 0.45) < 1e-6 and abs(z_top - 0.54) < 1e-6, (z_crate, z_top)


def test_main_evaluates_every_function_clean(built):
    for name, (d, m) in built.items():
        exe = f"./{m['build']['executable']}"
        for f in m["functions"]:
            out = _run([exe, f["name"]], d)
            _clean(out)
            assert out.returncode == 0 and out.stdout.startswith(f"function {f['name']}"), (name, out.stderr)


def test_main_refuses_bad_arguments(built):
    for name, (d, m) in built.items():
        exe = f"./{m['build']['executable']}"
        for args, expected in ((["nosuch"], "function: no function 'nosuch'"),
                               (["x" * 5000], "function: no function 'xxxx"),
                               (["phi", "extra"], "expected at most 1 argument")):
            out = _run([exe, *args], d)
            _clean(out)
            assert out.returncode == 2 and expected in out.stderr, (name, args, out.stderr)
            assert len(out.stderr) < 2000


# Models whose stepper needs a shorter step than the programs' 1 ms default: the capstan winch's
# rope-material mode (m_s = 1 g on EA = 1e5 N) is stiff; at 1 ms its program stops at step 1 with
# "Newton did not converge (reduce h)", exit 1 (checked below), and runs at 20 µs.
DEMO_STEP = {"capstan_winch": "2e-5"}


def test_simulate_runs_clean(built):
    for name, (d, m) in built.items():
        for prog in m["build"].get("programs", []):
            step = [DEMO_STEP[name]] if name in DEMO_STEP else []
            out = _run([f"./{prog[:-2]}", "0.05", *step], d)
            _clean(out)
            assert out.returncode == 0 and "steps = " in out.stdout, (name, out.stderr)
            if step:                                   # the default step fails loudly, never a wrong state
                out = _run([f"./{prog[:-2]}", "0.05"], d)
                _clean(out)
                assert out.returncode == 1 and "reduce h" in out.stderr, (name, out.returncode, out.stderr)


@pytest.mark.parametrize("args, named", BAD_SIMULATE, ids=[" ".join(a) or "empty" for a, _ in BAD_SIMULATE])
def test_simulate_refuses_hostile_arguments(built, args, named):
    for name, (d, m) in built.items():
        for prog in m["build"].get("programs", []):
            out = _run([f"./{prog[:-2]}", *args], d)
            _clean(out)
            assert out.returncode == 2, (name, args, out.returncode, out.stderr)
            assert f": {named}" in out.stderr or named in out.stderr, (name, args, out.stderr)
            assert "usage:" in out.stderr or "too small" in out.stderr or "after t0" in out.stderr
