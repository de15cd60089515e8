"""Bad input named before any work (review of the command line): output paths that cannot be
written, a garment too small for its count, a sheet scene's file given to the body runner, a
joints bag given to it, a scene file that is not UTF-8, topic names ROS would refuse, an
avatar file's unknown keys and units, options the settled textile tests do not use, and a
benchmark's flags named as that benchmark has them. Each fails in under a second (no
calibration, no bag read past its first messages)."""

from __future__ import annotations

import pytest
import yaml

from cloth_mg_ros.cli.main import main
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.share import config_path
from cloth_mg_ros.io.topic_names import is_absolute_topic
from cloth_mg_ros.motion.avatar import Avatar

REPO_BVH = "test/data/mocap/07_01.bvh"


def _error(capsys, *argv: str) -> str:
    assert main(list(argv)) == 2
    return capsys.readouterr().err


@pytest.mark.parametrize("argv, flag", [
    (["run", "--scene", "drape", "--particles", "100", "--steps", "2", "--out", "{file}"],
     "--out {file}: exists and is not a folder"),
    (["bench", "matvec", "--particles", "100", "--json", "{file}/x.json"],
     "--json {file}/x.json: {file} is a file"),
    (["export-system", "--out", "{file}/sys.npz"], "--out {file}/sys.npz: {file} is a file"),
    (["materials", "--json", "{dir}"], "is a folder, not a file"),
])
def test_an_output_that_cannot_be_written_is_named_before_any_work(tmp_path, capsys, argv,
                                                                  flag):
    file = tmp_path / "a_file"
    file.write_text("x")
    fill = {"file": str(file), "dir": str(tmp_path)}
    err = _error(capsys, *[a.format(**fill) for a in argv])
    assert flag.format(**fill) in err


def test_a_garment_too_small_for_its_count_is_refused_before_the_calibration(capsys):
    err = _error(capsys, "run", "--scene", "walking", "--particles", "20", "--steps", "1")
    assert "particles 20 is too few for a dress: at least 100" in err


def test_a_sheet_scenes_params_file_is_not_run_as_a_body_scene(tmp_path, capsys):
    path = tmp_path / "drape.yaml"
    path.write_text("/**:\n  ros__parameters:\n    scene: drape\n    particles: 200\n")
    assert "is a sheet scene: run it as --scene drape" in _error(
        capsys, "run", "--scene", str(path), "--steps", "2", "--out", str(tmp_path / "o"))


def test_a_joints_bag_given_to_the_body_runner_is_named(tmp_path, capsys):
    bag = tmp_path / "joints"
    assert main(["bag", "from-bvh", REPO_BVH, str(bag), "--body-input", "joints",
                 "--skeleton", "kinect32"]) == 0
    capsys.readouterr()
    err = _error(capsys, "run", "--scene", "walking", "--bag", str(bag), "--particles", "200",
                 "--steps", "2", "--out", str(tmp_path / "o"))
    assert "32 poses per message, where the avatar has 16 segments" in err


def test_a_scene_file_that_is_not_utf8_is_named(tmp_path, capsys):
    path = tmp_path / "latin1.yaml"
    path.write_bytes(config_path("walking.yaml").read_bytes() + "# caf\xe9\n".encode("latin-1"))
    assert "is not readable YAML" in _error(capsys, "run", "--scene", str(path), "--steps", "1")


@pytest.mark.parametrize("name, ok", [
    ("/cloth/marker", True), ("/a/b_1", True), ("/_x", True), ("/", False), ("/a/", False),
    ("/a b", False), ("/1a", False), ("/a,/b", False), ("cloth", False), ("/caf\u00e9", False)])
def test_topic_names_as_ros_takes_them(name, ok):
    assert is_absolute_topic(name) is ok


def test_bad_topic_names_are_refused_before_a_bag_is_written_or_a_recording_waits(tmp_path,
                                                                                  capsys):
    err = _error(capsys, "bag", "from-bvh", REPO_BVH, str(tmp_path / "o"), "--topic", "/")
    assert "--topic must be an absolute ROS topic name" in err
    assert not (tmp_path / "o").exists()
    err = _error(capsys, "record", str(tmp_path / "r"), "--topics", "/cloth/marker,/cloth/stats",
                 "--duration", "1")
    assert "'/cloth/marker,/cloth/stats' is not an absolute ROS topic name" in err


def test_an_avatar_files_unknown_keys_and_units_are_named():
    data = yaml.safe_load(config_path("avatar.yaml").read_text())
    Avatar.from_dict(data, "avatar")  # as shipped
    with pytest.raises(ClothInputError, match="unknown key 'ground_clearence'"):
        Avatar.from_dict({**data, "ground_clearence": 0.02}, "avatar")
    with pytest.raises(ClothInputError, match=r"segments\[0\]: unknown key 'raduis'"):
        Avatar.from_dict({**data, "segments": [{**data["segments"][0], "raduis": 5},
                                               *data["segments"][1:]]}, "avatar")
    with pytest.raises(ClothInputError, match="units must be"):
        Avatar.from_dict({**data, "units": {"length": "cm", "angle": "deg"}}, "avatar")


@pytest.mark.parametrize("scene, flag", [
    ("tensile", "--stretch"), ("tensile", "--steps"), ("cusick", "--stretch"),
    ("cusick", "--mesh"), ("cantilever", "--steps"), ("cantilever", "--tol"),
    ("cantilever", "--scheme"), ("cantilever", "--friction"), ("cantilever", "--compression"),
    ("buckle", "--tol"), ("buckle", "--spectral-radius"), ("capstan", "--spectral-radius"),
    ("tensile", "--scheme"), ("swing", "--friction")])
def test_the_textile_tests_refuse_options_they_do_not_use(capsys, scene, flag):
    """Refused by name before any work; --scheme, --spectral-radius, --friction and
    --compression too, which other scenes take from the schema when not given (the
    cantilever used to settle as it would have without them)."""
    value = {"--mesh": "lattice", "--scheme": "genalpha", "--compression": "buckle",
             "--steps": "5", "--levels": "2"}.get(flag, "0.5")
    assert f"{flag} is not an option of the {scene} scene" in _error(
        capsys, "run", "--scene", scene, flag, value)


def test_an_unknown_scene_is_named_with_every_scene_run_knows(capsys):
    err = _error(capsys, "run", "--scene", "nosuch", "--steps", "1")
    assert "unknown scene 'nosuch'" in err
    for scene in ("drape", "cantilever", "buckle", "dressing", "walking", "jump", ".yaml"):
        assert scene in err


@pytest.mark.parametrize("argv, message", [
    (["bench", "profile", "--ticks", "0"], "bench profile: --ticks must be a positive integer"),
    (["bench", "pareto", "--sizes", "-1"], "bench pareto: --sizes must be integers in"),
    (["bench", "walking", "--particles", "99999999"], "--particles must be integers in 16..200000"),
    (["run", "--scene", "drape", "--particles", "50000000"], "--particles must be in 16..200000"),
    (["bench", "faults", "--start-timeout", "-5"], "--start-timeout must be a positive number"),
])
def test_a_benchmarks_flags_are_named_as_it_has_them(capsys, argv, message):
    assert message in _error(capsys, *argv)
