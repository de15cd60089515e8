"""One parameter schema (config.schema): the scene loader, the simulation's options, the node's
parameter table, descriptors and run-time checks, `cloth_node --help`, `cloth-mg run --help`
and the docs' table all come from it, and agree; a parameter added to the schema alone shows
up in every one of them."""

from __future__ import annotations

import importlib.util
import pickle
import re
from dataclasses import MISSING, FrozenInstanceError, fields
from pathlib import Path

import pytest

from cloth_mg_ros.config import schema
from cloth_mg_ros.config.scenes import load_scene
from cloth_mg_ros.config.schema import (
    NODE,
    PARAMETERS,
    ROS,
    SHARED,
    Parameter,
    SceneParams,
    markdown_table,
    option_help,
    rows,
)
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.sim.garment_sim import BodySimOptions

REPO = Path(__file__).resolve().parents[1]
HELP_LINE = re.compile(r"^  (\w+) \(default (.*)\)$", flags=re.MULTILINE)


def _squash(text: str) -> str:
    """Text without whitespace (argparse and textwrap break lines where they like)."""
    return "".join(text.split())


def _ros_parameters():
    pytest.importorskip("rcl_interfaces", reason="ROS 2 message packages not installed")
    from cloth_mg_ros.ros import parameters

    return parameters


def _help_entries(text: str) -> dict[str, tuple[str, str]]:
    """name: (default as printed, the text below it) of `cloth_node --help`."""
    found = list(HELP_LINE.finditer(text))
    return {m.group(1): (m.group(2), text[m.end():found[i + 1].start()
                                           if i + 1 < len(found) else len(text)])
            for i, m in enumerate(found)}


def _run_help(capsys) -> str:
    from cloth_mg_ros.cli.main import main

    with pytest.raises(SystemExit) as done:
        main(["run", "--help"])
    assert done.value.code == 0
    return capsys.readouterr().out


def _write_scene(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "my_scene.yaml"
    path.write_text("/**:\n  ros__parameters:\n" + body)
    return path


# -- they agree ------------------------------------------------------------------------------
def test_the_loader_knows_every_parameter_with_the_schemas_kinds_and_defaults(tmp_path):
    params = load_scene(str(_write_scene(tmp_path, "    garment: dress\n")))
    assert list(params) == list(PARAMETERS)
    assert params.scene == "my_scene"  # a file that does not name itself
    for name, p in PARAMETERS.items():
        if name != "scene":
            assert params[name] == getattr(params, name) == p.default, name
    walking = load_scene("walking")
    assert walking.particles == "auto" and walking.tolerance == "auto" and walking.lod is True


def test_the_node_declares_every_parameter_with_the_schemas_types_ranges_and_run_time():
    parameters = _ros_parameters()
    from rcl_interfaces.msg import ParameterType

    kinds = {str: ParameterType.PARAMETER_STRING, int: ParameterType.PARAMETER_INTEGER,
             float: ParameterType.PARAMETER_DOUBLE, bool: ParameterType.PARAMETER_BOOL,
             tuple: ParameterType.PARAMETER_STRING_ARRAY,
             schema.Numbers: ParameterType.PARAMETER_DOUBLE_ARRAY}
    body, scene = parameters.scene_defaults("walking")
    table = parameters.parameter_table(body, scene)
    assert list(table) == [n for n, p in PARAMETERS.items() if p.scope != ROS]
    for name, spec in table.items():
        p = PARAMETERS[name]
        assert spec.default == scene[name], name
        assert spec.read_only is not p.runtime, name
        desc = parameters.descriptor(name, spec)
        if p.auto:
            assert desc.dynamic_typing and desc.type == ParameterType.PARAMETER_NOT_SET, name
        else:
            assert desc.type == kinds[p.type] and isinstance(spec.default, p.type), name
        ranges = ([(r.from_value, r.to_value) for r in desc.integer_range]
                  + [(r.from_value, r.to_value) for r in desc.floating_point_range])
        assert ranges == ([tuple(p.range)] if p.range else []), name
        assert p.meaning in desc.description and p.unit in desc.description, name
        if p.choices:
            assert all(c in desc.additional_constraints for c in p.choices), name
    assert parameters.MAX_TOLERANCE == PARAMETERS["tolerance"].range[1]
    # sheet scenes: the node's own defaults where the schema has one
    body, sheet = parameters.scene_defaults("drape")
    sheet_table = parameters.parameter_table(body, sheet)
    assert not body and sheet_table["tick_mode"].default == "timer"
    assert sheet_table["scene"].default == "drape"
    # the solver is the body scenes' own: the project's multigrid, not the paper's baseline
    assert sheet_table["solver"].default == PARAMETERS["solver"].default == "mpcg"


def test_run_time_changes_are_checked_by_the_schema():
    parameters = _ros_parameters()
    check = parameters.check_runtime_change
    assert check("solver", "bscg") is None and check("tolerance", 1e-5) is None
    assert check("tolerance", "auto") is None and check("rate_hz", 60.0) is None
    assert "magic" in check("solver", "magic")
    assert "tolerance" in check("tolerance", 0.9) and "tolerance" in check("tolerance", -1.0)
    assert "rate_hz" in check("rate_hz", 5000.0)
    assert check("garment", "kilt") is None  # read-only: rclpy refuses it first
    assert [n for n, p in PARAMETERS.items() if p.runtime] == ["solver", "tolerance",
                                                                "release_force", "rate_hz"]
    values = parameters.check_parameters({"particles": 300, "tick_mode": "timer"})
    assert values.particles == 300 and values.tick_mode == "timer"
    with pytest.raises(ClothInputError, match="parameter: tick_mode: unknown tick_mode"):
        parameters.check_parameters({"tick_mode": "sometimes"})


def test_cloth_node_help_lists_every_parameter_with_its_default_values_and_run_time():
    parameters = _ros_parameters()
    entries = _help_entries(parameters.usage_text())
    assert list(entries) == list(PARAMETERS)
    walking = load_scene("walking")
    for name, (default, text) in entries.items():
        p = PARAMETERS[name]
        assert default == repr(walking[name]), name
        assert _squash(p.meaning) in _squash(text), name
        if p.unit:
            assert _squash(f"[{p.unit}") in _squash(text), name
        if p.type is not bool and not (p.type is str and not p.choices):
            assert _squash(p.values()) in _squash(text), name
        assert ("may be set while running" in " ".join(text.split())) is p.runtime, name


def test_cloth_mg_run_help_shows_the_shared_parameters_it_has_options_for(capsys):
    from cloth_mg_ros.cli.run import RUN_SCENE_OPTIONS

    text = _squash(_run_help(capsys))
    assert {"particles", "solver", "tolerance", "garment"} <= set(RUN_SCENE_OPTIONS.values())
    for flag, name in RUN_SCENE_OPTIONS.items():
        p = PARAMETERS[name]
        assert p.scope == SHARED, name
        assert _squash(flag) in text
        assert _squash(option_help(name).replace("%%", "%")) in text, flag
        assert _squash(f"default {schema._show(p.default)}") in _squash(option_help(name))
        if p.type is not str or p.choices:
            assert _squash(p.values()) in text, flag


def test_the_docs_table_lists_every_parameter_as_the_schema_has_it():
    spec = importlib.util.spec_from_file_location("doc_conf", REPO / "doc" / "conf.py")
    conf = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(conf)
    walking = load_scene("walking")
    table = conf.parameter_rows()
    assert table == rows(walking)
    assert [r["name"] for r in table] == list(PARAMETERS)
    for row in table:
        p = PARAMETERS[row["name"]]
        assert row["default"] == walking[p.name] and row["kind"] == p.kind
        assert row["runtime"] is p.runtime and row["scope"] == p.scope
        assert row["unit"] == p.unit and row["meaning"] == p.meaning
    page = conf.parameter_markdown(table)
    for p in PARAMETERS.values():
        line = next(line for line in page.splitlines() if line.startswith(f"| `{p.name}` |"))
        cells = [c.strip() for c in line.split(" | ")]
        assert cells[1] == p.kind and cells[2] == f"`{schema._show(walking[p.name])}`"
        assert cells[3] == p.unit and cells[5] == ("run time" if p.runtime else "start")
        if p.type is not bool:
            assert cells[4] == p.values().replace("|", "\\|"), p.name


def test_body_sim_options_have_no_defaults_of_their_own_and_take_every_shared_field_from_a_scene():
    """The simulation's options named like scene parameters are the configuration's: no
    default of their own (only from_scene, from a SceneParams, fills them), the schema's
    defaults through config.schema.body_options, a scene's values through from_scene."""
    shared = [f for f in fields(BodySimOptions) if f.name in PARAMETERS]
    assert {f.name for f in shared} >= {"garment", "particles", "solver", "tolerance",
                                        "levels", "substeps", "max_substep_motion",
                                        "max_step", "floor", "self_contact", "threads",
                                        "scheme", "friction", "compression", "grippers"}
    for f in shared:
        assert PARAMETERS[f.name].scope == SHARED, f.name
        assert f.default is MISSING and f.default_factory is MISSING, f.name
    with pytest.raises(TypeError):
        BodySimOptions()
    plain = schema.body_options()
    for f in shared:
        if f.name != "levels":
            assert getattr(plain, f.name) == PARAMETERS[f.name].default, f.name
    scene = load_scene("running")
    options = BodySimOptions.from_scene(scene, particles=600)
    for f in shared:
        if f.name not in ("particles", "levels"):
            assert getattr(options, f.name) == scene[f.name], f.name
    assert options.particles == 600 and options.levels is None  # levels 0: the mesh decides


def test_the_configuration_is_typed_frozen_and_a_mapping():
    """SceneParams is one frozen dataclass field per parameter, typed by its kind (no
    attribute lookup by name at run time), read as attributes or as a Mapping; a change is
    a checked copy."""
    params = schema.defaults()
    names = [f.name for f in fields(params)]
    assert names == list(PARAMETERS) == list(params)
    assert type(params) is schema.config_class(tuple(PARAMETERS))
    types = {f.name: f.type for f in fields(params)}
    assert types["particles"] == int | str and types["friction"] is float
    assert types["floor"] is bool and types["grippers"] is tuple
    assert params.garment == params["garment"] == dict(params)["garment"] == "dress"
    with pytest.raises(FrozenInstanceError):
        params.friction = 0.3
    changed = params.replace(friction=0.3)
    assert changed.friction == 0.3 and params.friction == 0.5 and changed != params
    with pytest.raises(ClothInputError, match="friction"):
        params.replace(friction=-1.0)
    with pytest.raises(AttributeError):
        params.no_such_parameter  # noqa: B018 - the read itself is the test


# -- bad values --------------------------------------------------------------------------------
@pytest.mark.parametrize("line, names", [
    ("max_step: 2.0", ["max_step", "2.0", "0.001..0.25"]),
    ("substeps: 0", ["substeps", "0", "1..64"]),
    ("garment: kilt", ["unknown garment 'kilt'", "skirt, dress, cape, top"]),
    ("solver: magic", ["unknown solver 'magic'"]),
    ("floor: 'yes'", ["floor", "true or false", "'yes'"]),
    ("particles: 5", ["particles", "16..200000", "5"]),
    ("rate_hz: 0.0", ["rate_hz", "0.0"]),  # a node-only key is checked too
    ("tick_mode: sometimes", ["unknown tick_mode 'sometimes'"]),
])
def test_a_bad_value_in_a_scene_file_is_refused_naming_file_key_and_value(tmp_path, line,
                                                                          names):
    path = _write_scene(tmp_path, f"    {line}\n")
    with pytest.raises(ClothInputError) as error:
        load_scene(str(path))
    message = str(error.value)
    assert str(path) in message
    for name in names:
        assert name in message, message


def test_scene_params_are_read_only_checked_copies_and_pickle():
    params = load_scene("walking")
    with pytest.raises(FrozenInstanceError):
        params.garment = "cape"
    changed = params.replace(garment="cape", particles=300)
    assert changed.garment == "cape" and params.garment == "dress"
    assert dict(changed) == {**params.as_dict(), "garment": "cape", "particles": 300}
    with pytest.raises(ClothInputError, match="unknown garment 'kilt'"):
        params.replace(garment="kilt")
    with pytest.raises(AttributeError, match="no attribute 'wings'"):
        params.wings  # noqa: B018 - the attribute access is the test
    assert pickle.loads(pickle.dumps(params)) == params
    assert isinstance(params, SceneParams)
    assert schema.check("max_step", 0.2) == 0.2
    budget = schema.check("tick_budget", 1)
    assert budget == 1.0 and isinstance(budget, float)
    assert schema.check("material", "Silk") == "Silk"  # get_material folds the case


# -- adding a parameter ------------------------------------------------------------------------
@pytest.fixture
def wind(monkeypatch):
    """Two parameters that exist in the schema alone: a shared one and a node-only run-time
    one."""
    added = [Parameter("wind_speed", "double", 0.0, "body scenes: a steady wind along +x",
                       unit="m/s", range=(0.0, 30.0)),
             Parameter("gust_mode", "string", "steady", "how the wind varies",
                       choices=("steady", "gusty"), runtime=True, scope=NODE)]
    for p in added:
        monkeypatch.setitem(PARAMETERS, p.name, p)
    return added


def test_a_parameter_added_to_the_schema_alone_appears_everywhere(wind, tmp_path, capsys):
    # the scene loader: a default, a value from a file, a bad value refused
    assert load_scene("walking").wind_speed == 0.0
    path = _write_scene(tmp_path, "    wind_speed: 3\n    gust_mode: gusty\n")
    params = load_scene(str(path))
    assert params.wind_speed == 3.0 and params.gust_mode == "gusty"
    with pytest.raises(ClothInputError, match="wind_speed must be a number in 0..30"):
        load_scene(str(_write_scene(tmp_path, "    wind_speed: 99.0\n")))
    # the docs
    table = rows()
    assert {"wind_speed", "gust_mode"} <= {r["name"] for r in table}
    page = markdown_table()
    assert "| `wind_speed` | double | `0` | m/s | a number in 0..30 | start |" in page
    assert "| `gust_mode` | string | `steady` |  | one of steady, gusty | run time | node |" \
        in page
    # the node: declared with its range, checked at run time, in --help
    parameters = _ros_parameters()
    table = parameters.parameter_table(*parameters.scene_defaults("walking"))
    assert table["wind_speed"].float_range == (0.0, 30.0) and table["wind_speed"].read_only
    assert not table["gust_mode"].read_only
    assert "gusty" in parameters.descriptor("gust_mode", table["gust_mode"]).additional_constraints
    assert "unknown gust_mode 'stormy'" in parameters.check_runtime_change("gust_mode", "stormy")
    entries = _help_entries(parameters.usage_text())
    assert entries["wind_speed"][0] == "0.0" and "m/s" in entries["wind_speed"][1]
    assert "may be set while running" in entries["gust_mode"][1]


def test_the_skeleton_parameter_offers_every_joint_layout():
    from cloth_mg_ros.config.schema import PARAMETERS
    from cloth_mg_ros.motion.skeletons import SKELETONS

    assert PARAMETERS["skeleton"].choices == ("kinect32", "mediapipe33", "cmu31")
    assert set(PARAMETERS["skeleton"].choices) == set(SKELETONS)
