"""The committed C packages in ``generated/`` are exactly what ncgen generates today.

Every model file ``examples/*.toml`` (a TOML file with ``[[members]]``; optimal-control
problem files are not models) has its package in ``generated/<model name>/``; this
test regenerates them all into a temporary directory and compares them byte for byte, so
generated code is reviewed like code: a change to the generator, the templates or an
example shows up in the diff of the commit that causes it.

The constants inside the kernels are computed without BLAS or LAPACK
(:mod:`ncgen.reproducible`), whose kernels are chosen per CPU and sum in different orders.
The consistent initial state (``q0``, ``v0``, ``λ0``, ``z0`` in the metadata) comes from
sparse Newton and KKT solves, whose last bits do depend on them; so a numeric literal may
differ by round-off (``RTOL``, ``ATOL``), and with it the sha256 digests that cover it.
Anything else — a token, a line, a number beyond round-off — is a difference.  To update
the packages after an intended change, run::

    python tests/test_generated_up_to_date.py
"""
from __future__ import annotations

import difflib
import re
import sys
import time
import tomllib
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
GENERATED = ROOT / "generated"
#: Generating every shipped package must stay cheap: CPU seconds (not wall time, which the load
#: of a shared machine inflates 3–10×).
TIME_BUDGET = 60.0
#: Lines of unified diff shown per differing file.
DIFF_LINES = 12
#: Round-off allowed between numeric literals: |a − b| ≤ RTOL max(|a|, |b|) + ATOL.
RTOL, ATOL = 1e-9, 1e-12
NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")
DIGEST = re.compile(r"\b[0-9a-f]{64}\b")


def model_files() -> list[Path]:
    """The model files among ``examples/*.toml``."""
    return [p for p in sorted(EXAMPLES.glob("*.toml")) if "members" in tomllib.loads(p.read_text())]


def regenerate(root: Path) -> dict[str, float]:
    """Generate the package of every ``examples/*.toml`` into ``root/<model>``; returns the
    time (s) each took, model building (or reading from the store of built models) included.
    Models with ``[[contacts]]`` are built with nonsmooth contacts, so that their packages hold
    the contact half of the compiled stepper (``templates/c/runtime/ncgen_contact.h``)."""
    import ncgen as nc

    times = {}
    for path in model_files():
        start = time.process_time()
        contacts = "nonsmooth" if "contacts" in tomllib.loads(path.read_text()) else "smooth"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")          # e.g. redundant constraints dropped
            model = nc.System.from_toml(path).build(contacts=contacts)
        nc.generate(model, root / model.name)
        times[model.name] = time.process_time() - start
    return times


def differences(expected: Path, actual: Path) -> list[str]:
    """Human-readable differences between two trees of packages (empty when equal)."""
    out = []
    exp = {p.relative_to(expected) for p in expected.rglob("*") if p.is_file()} if expected.is_dir() else set()
    act = {p.relative_to(actual) for p in actual.rglob("*") if p.is_file()}
    for rel in sorted(act - exp):
        out.append(f"missing from generated/: {rel}")
    for rel in sorted(exp - act):
        out.append(f"not generated any more (remove it): generated/{rel}")
    for rel in sorted(exp & act):
        old, new = (expected / rel).read_bytes(), (actual / rel).read_bytes()
        if old == new or same_up_to_roundoff(old.decode(errors="replace"), new.decode(errors="replace")):
            continue
        diff = list(difflib.unified_diff(old.decode(errors="replace").splitlines(),
                                         new.decode(errors="replace").splitlines(),
                                         f"generated/{rel} (committed)", f"{rel} (generated now)",
                                         n=1, lineterm=""))
        changed = sum(1 for line in diff if line[:1] in "+-" and line[:3] not in ("+++", "---"))
        shown = diff[:DIFF_LINES] + ([f"... ({len(diff) - DIFF_LINES} more diff lines)"]
                                     if len(diff) > DIFF_LINES else [])
        out.append(f"differs: generated/{rel} ({changed} changed lines)\n    " + "\n    ".join(shown))
    return out


def same_up_to_roundoff(old: str, new: str) -> bool:
    """Whether two texts differ at most in the last bits of numeric literals (and so in the
    sha256 digests of them)."""
    a, b = old.splitlines(), new.splitlines()
    if len(a) != len(b):
        return False
    for x, y in zip(a, b):
        if x == y:
            continue
        x, y = DIGEST.sub("#", x), DIGEST.sub("#", y)
        if NUMBER.sub("0", x) != NUMBER.sub("0", y):
            return False
        for m, n in zip(NUMBER.findall(x), NUMBER.findall(y)):
            u, v = float(m), float(n)
            if abs(u - v) > RTOL * max(abs(u), abs(v)) + ATOL:
                return False
    return True


def test_roundoff_comparison_tells_roundoff_from_changes():
    base = "const casadi_real q0[2] = {0.14776010333066975, 1.3877787807814457e-17};"
    assert same_up_to_roundoff(base, base.replace("0.14776010333066975", "0.14776010333066977")
                               .replace("1.3877787807814457e-17", "0.0"))
    assert not same_up_to_roundoff(base, base.replace("0.14776010333066975", "0.1478"))
    assert not same_up_to_roundoff("a1=(a2*a3);", "a1=(a2*a4);")
    assert not same_up_to_roundoff("a1=(a2*a3);", "a1=(a2+a3);")
    assert not same_up_to_roundoff("x\ny", "x")
    assert same_up_to_roundoff('"content_hash": "' + "a" * 64 + '"', '"content_hash": "' + "b" * 64 + '"')


def test_generated_packages_are_up_to_date(tmp_path):
    times = regenerate(tmp_path)
    problems = differences(GENERATED, tmp_path)
    assert not problems, (
        f"{len(problems)} difference(s) between the committed generated/ packages and what ncgen "
        f"generates now. If the change is intended, run 'python tests/test_generated_up_to_date.py' "
        f"and commit generated/ with it.\n" + "\n".join(problems))
    total = sum(times.values())
    slowest = ", ".join(f"{k} {v:.1f} s" for k, v in sorted(times.items(), key=lambda kv: -kv[1])[:3])
    assert total < TIME_BUDGET, f"generating the shipped packages took {total:.0f} s (slowest: {slowest})"


def test_every_example_is_shipped():
    names = {p.name for p in GENERATED.iterdir() if p.is_dir()}
    assert names, "generated/ is empty: run 'python tests/test_generated_up_to_date.py'"
    assert len(names) == len(model_files()), (
        f"generated/ holds {sorted(names)}; expected one package per model file in examples/")


if __name__ == "__main__":
    import shutil
    import tempfile

    sys.path.insert(0, str(ROOT))        # regenerate with this checkout's ncgen, not an installed one

    with tempfile.TemporaryDirectory() as tmp:
        took = regenerate(Path(tmp))
        for name in sorted(took):
            target = GENERATED / name
            shutil.rmtree(target, ignore_errors=True)
            shutil.copytree(Path(tmp) / name, target)
            print(f"generated/{name}: {took[name]:.2f} s")
    stale = sorted(p.name for p in GENERATED.iterdir() if p.is_dir() and p.name not in took)
    for name in stale:
        shutil.rmtree(GENERATED / name)
        print(f"generated/{name}: removed (no examples/*.toml defines it)")
    sys.exit(0)
