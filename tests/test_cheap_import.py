"""``import ncgen`` and the CLI's start load no heavy library the command does not need
(issue 34), and every public name still resolves through the lazy re-exports."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("sympy", "scipy", "matplotlib", "pandas", "dask", "zarr", "jinja2", "casadi", "yourdfpy", "trimesh", "asyncio")


def loaded_after(code: str) -> list[str]:
    """The HEAVY modules in ``sys.modules`` after running ``code`` in a fresh interpreter."""
    probe = f"{code}\nimport json, sys\nprint(json.dumps(sorted(m for m in {HEAVY!r} if m in sys.modules)))"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, env=env, cwd=ROOT,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_import_ncgen_loads_no_heavy_library():
    assert loaded_after("import ncgen") == []


def test_cli_start_loads_only_its_subcommand():
    code = ("import sys\nfrom ncgen.cli import build_parser, SUBCOMMANDS\n"
            "parser = build_parser('derive')\n"
            "assert list(SUBCOMMANDS) == ['derive'], list(SUBCOMMANDS)\n"
            "assert 'ncgen.cli.simulate' not in sys.modules")
    assert loaded_after(code) == []


def test_a_name_loads_its_layer_on_first_use():
    assert "sympy" in loaded_after("import ncgen\nncgen.coordinate_type('rr').derivation")


def test_every_public_name_resolves():
    import ncgen

    for name in ncgen.__all__:
        assert getattr(ncgen, name) is not None, name
    assert set(ncgen.__all__) <= set(dir(ncgen))
    assert ncgen.System.__module__ == "ncgen.model.system"
    assert ncgen.simulate.__module__ == "ncgen.runtime.simulation"
    assert ncgen.viz.__name__ == "ncgen.viz" and ncgen.robots.__name__ == "ncgen.robots"
    assert ncgen.modes.__module__ == "ncgen.analysis.modes"      # the function, not its module
    from ncgen import System, __version__
    assert System is ncgen.System and __version__


def test_unknown_name_is_an_attribute_error_naming_it():
    import ncgen

    with pytest.raises(AttributeError, match="'Sytem'"):
        ncgen.Sytem
    assert not hasattr(ncgen, "_private_thing")


def test_full_parser_lists_every_subcommand_and_a_run_names_one():
    from ncgen.cli import SUBCOMMAND_MODULES, SUBCOMMANDS, build_parser

    parser = build_parser()
    assert set(SUBCOMMAND_MODULES) == set(SUBCOMMANDS)      # registered in import order: other tests import some first
    assert set(parser._subparsers._group_actions[0].choices) == set(SUBCOMMAND_MODULES)
    only = build_parser("modes")
    assert set(only._subparsers._group_actions[0].choices) == {"modes"}


@pytest.mark.parametrize("source", [pytest.param("ur5", marks=pytest.mark.slow), "double_pendulum.toml"])
def test_later_cli_run_of_a_stored_tree_needs_no_sympy(tmp_path, source):
    """``ncgen simulate robot.urdf`` (the UR5, slow tier) or ``model.toml`` (a double pendulum,
    the same path at a tenth of the cost) a second time: the model, its joint-space ODE and
    tree map come from the store, so SymPy (and SciPy, matplotlib) is never imported; the
    first run builds from the formulas shipped as generated data, without SymPy too."""
    import ncgen as nc

    urdf = str(ROOT / "examples" / source) if source.endswith(".toml") else str(nc.robots.urdf_path(source))
    run = (f"import os\nos.environ['NCGEN_CACHE_DIR'] = {str(tmp_path / 'cache')!r}\n"
           "os.environ.pop('NCGEN_MODEL_CACHE', None)\n"
           f"from ncgen.cli import main\nassert main(['simulate', {urdf!r}, '--t-end', '0.05']) == 0")
    assert "sympy" not in loaded_after(run)
    assert loaded_after(run) == ["casadi"]
