"""Coverage of the MJCF import: the share of the MJCF files shipped by gymnasium
(``envs/mujoco/assets``) and dm_control (``suite``), and of the Menagerie models the tests
use when ``$NCGEN_MENAGERIE`` names a mujoco_menagerie checkout (:data:`MENAGERIE`), that
``nc.System.from_mjcf`` imports without an unsupported-feature warning (issue 40's target:
≥ 80 %).

Each file is one of: ``ok`` (imported, nothing left out), ``warned`` (imported; the
MjcfWarning's items counted), ``refused`` (a ModelError: what the import cannot represent
at all, e.g. a mesh giving mass).  Only the import is run (no build).  With gymnasium 1.4.0
and dm_control 1.0.50: 27 of 33 files (82 %) ok, 5 warned, 1 refused; with the Menagerie's
UR5e, Go1 and Cassie 29 of 36 (81 %) (docs/mjcf.md); with the UR5e, Panda and Gen3 (no Go1,
no Cassie) 30 of 36 (83 %).
``python benchmarks/mjcf_coverage.py [--verbose]``."""
from __future__ import annotations

import importlib.util
import os
import platform
import sys
import warnings
from pathlib import Path

import ncgen as nc
from ncgen.errors import NcgenError
from ncgen.model.mjcf import MjcfWarning


#: The Menagerie models of tests/test_mjcf_menagerie.py: an arm, a quadruped, a loop robot,
#: and the further arms checked there when present (Panda, Kinova Gen3).
MENAGERIE = ("universal_robots_ur5e/ur5e.xml", "unitree_go1/go1.xml", "agility_cassie/cassie.xml",
             "franka_emika_panda/panda.xml", "kinova_gen3/gen3.xml")


def shipped() -> dict[str, Path]:
    out = {}
    root = os.environ.get("NCGEN_MENAGERIE")
    for name in MENAGERIE if root else ():
        if (Path(root) / name).is_file():
            out[f"menagerie/{name}"] = Path(root) / name
    for pkg, sub in (("gymnasium", "envs/mujoco/assets"), ("dm_control", "suite")):
        spec = importlib.util.find_spec(pkg)
        if spec is None or spec.origin is None:
            print(f"{pkg}: not installed (pip install {pkg.replace('_', '-')})")
            continue
        for f in sorted((Path(spec.origin).parent / sub).glob("*.xml")):
            out[f"{pkg}/{f.name}"] = f
    return out


def classify(path: Path) -> tuple[str, str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            system = nc.System.from_mjcf(path)
        except NcgenError as e:
            return "refused", str(e).splitlines()[0]
    if any(issubclass(w.category, MjcfWarning) for w in caught):
        return "warned", f"{len(system.mjcf_unsupported)} item(s): " + "; ".join(system.mjcf_unsupported[:3])
    return "ok", f"{len(system.members)} bodies, {len(system.joints)} joints"


def main(argv: list[str]) -> None:
    verbose = "--verbose" in argv
    print(f"python {platform.python_version()}, ncgen MJCF import, {platform.machine()}")
    files = shipped()
    if not files:
        print("no MJCF files found: install gymnasium and dm_control (the test extras)")
        return
    counts = {"ok": 0, "warned": 0, "refused": 0}
    for key, path in files.items():
        status, detail = classify(path)
        counts[status] += 1
        print(f"{status:8s} {key:42s} {detail if verbose or status != 'ok' else ''}"[:240])
    n = len(files)
    print(f"{counts['ok']}/{n} files ({100 * counts['ok'] / n:.0f} %) import without an unsupported-feature warning; "
          f"{counts['warned']} with a warning, {counts['refused']} refused")


if __name__ == "__main__":
    main(sys.argv[1:])
