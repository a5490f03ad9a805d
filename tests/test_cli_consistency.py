"""The command line follows one set of rules: -o/--plot/--animate optional and checked alike in
every subcommand, helps that name every accepted model format, --floating-base for URDF,
--mjcf-contacts for MJCF."""
import argparse
from pathlib import Path

import pytest

from ncgen.cli import build_parser, main

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
FILE_COMMANDS = ("simulate", "equilibrium", "modes", "optimize")
MODEL_COMMANDS = ("simulate", "equilibrium", "modes", "check", "generate")


def subparsers():
    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return action.choices


@pytest.mark.parametrize("name", FILE_COMMANDS)
def test_file_options_are_optional_and_name_their_suffixes(name):
    options = {a.dest: a for a in subparsers()[name]._actions}
    for dest in ("output", "plot", "animate"):
        if dest in options:
            assert not options[dest].required and options[dest].default is None, (name, dest)
    assert ".png, .pdf, .svg" in options["plot"].help


@pytest.mark.parametrize("name", MODEL_COMMANDS)
def test_model_help_names_toml_and_urdf_and_floating_base(name):
    p = subparsers()[name]
    text = p.format_help()
    assert "TOML" in text and "URDF" in text and "--floating-base" in text


def test_same_suffix_errors_everywhere(capsys, tmp_path):
    model = str(EXAMPLES / "double_pendulum.toml")
    for argv in (["simulate", model, "--t-end", "0.1", "--plot", str(tmp_path / "x.jpg")],
                 ["equilibrium", model, "--plot", str(tmp_path / "x.jpg")],
                 ["modes", model, "--plot", str(tmp_path / "x.jpg")]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert "--plot" in err and "expected a file name ending in .png or .pdf or .svg" in err, argv


def test_simulate_without_output_prints_the_summary_only(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["simulate", str(EXAMPLES / "double_pendulum.toml"), "--t-end", "0.1"]) == 0
    assert "Trajectory of model" in capsys.readouterr().out and not list(tmp_path.iterdir())


def test_floating_base_is_for_urdf_only(capsys):
    assert main(["check", str(EXAMPLES / "double_pendulum.toml"), "--floating-base"]) == 1
    assert "--floating-base applies to URDF robots" in capsys.readouterr().err


@pytest.mark.parametrize("name", MODEL_COMMANDS + ("optimize", "sweep", "mpc"))
def test_every_model_command_takes_mjcf_contacts(name):
    text = subparsers()[name].format_help()
    assert "--mjcf-contacts" in text and "MJCF only (.xml): the geoms collide" in " ".join(text.split())


def test_mjcf_contacts_is_for_mjcf_only(capsys):
    assert main(["check", str(EXAMPLES / "double_pendulum.toml"), "--mjcf-contacts"]) == 1
    assert "--mjcf-contacts applies to MJCF models (.xml); " in capsys.readouterr().err


def test_floating_base_urdf(capsys, tmp_path):
    pytest.importorskip("yourdfpy")
    urdf = tmp_path / "arm.urdf"
    urdf.write_text("""<robot name="arm">
  <link name="base"><inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="arm"><inertial><origin xyz="0.5 0 0"/><mass value="1"/>
    <inertia ixx="0.01" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="10" velocity="5"/></joint>
</robot>""")
    assert main(["check", str(urdf)]) == 0
    fixed = capsys.readouterr().out
    assert main(["check", str(urdf), "--floating-base"]) == 0
    free = capsys.readouterr().out
    assert "DOF = 1" in fixed and "DOF = 7" in free        # a free base adds its 6 DOF
