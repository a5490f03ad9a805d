"""The committed packages in ``generated/`` compile without a warning at the optimisation
levels a user builds with (issue 35, class 14): ``-O2 -Wall -Wextra -pedantic -Werror``.
gcc's flow analysis (``-Wmaybe-uninitialized``) runs only when optimising, so the ``-O0``
builds of ``test_generated_sanitizers`` do not see what this one sees.  The kernel files
(CasADi's straight-line arithmetic, long to optimise) are left out; every other source and
program, which include the stepper's runtime (``templates/c/runtime/``), is compiled."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

GENERATED = Path(__file__).resolve().parent.parent / "generated"
CC = os.environ.get("CC") or shutil.which("gcc") or shutil.which("cc")
FLAGS = ["-std=c99", "-O2", "-Wall", "-Wextra", "-pedantic", "-Werror"]
PACKAGES = sorted(p.name for p in GENERATED.iterdir() if (p / "manifest.json").is_file())
#: Compiled in the fast tier: one package (the templates every package shares); the others, each a
#: whole -O2 build (22–68 s at load ≈ 20; the contact packages the longest), in the slow tier.
FAST_PACKAGES = {"double_pendulum"}


@pytest.mark.skipif(CC is None, reason="no C compiler on PATH")
@pytest.mark.parametrize("name", [n if n in FAST_PACKAGES else pytest.param(n, marks=pytest.mark.slow) for n in PACKAGES])
def test_committed_package_compiles_at_O2_without_warnings(tmp_path, name):
    package = GENERATED / name
    build = json.loads((package / "manifest.json").read_text())["build"]
    sources = [s for s in build["sources"] + [build["main"], *build.get("programs", [])] if "_kernels_" not in s]
    assert sources, f"{name}: no source besides the kernels"
    for src in sources:
        out = subprocess.run([CC, *FLAGS, "-I", str(package), "-c", str(package / src),
                              "-o", str(tmp_path / (Path(src).stem + ".o"))],
                             capture_output=True, text=True, timeout=600)
        assert out.returncode == 0, f"generated/{name}/{src} does not compile with {' '.join(FLAGS)}:\n" \
                                    f"{out.stderr[-3000:]}"


def test_contact_packages_are_among_them():
    assert {"box_stack", "boxes", "falling_chain"} <= set(PACKAGES)
