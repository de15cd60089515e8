"""A check shared by the tests of a scene parameter: the node's parameters and the body
scenes take it, and a sheet scene's `cloth-mg run` writes it to its summary."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from cloth_mg_ros.errors import ClothInputError


def check_scene_parameter(name: str, value: str, bad: str, flag: str, sheet: str,
                          out: Path) -> None:
    """``value`` of parameter ``name`` is taken by the node's parameters and the walking
    scene's options, ``bad`` is refused by name, and `cloth-mg run --scene SHEET FLAG VALUE`
    runs and names it in summary.json (in ``out``)."""
    from cloth_mg_ros.cli.main import main
    from cloth_mg_ros.config.scenes import load_scene
    from cloth_mg_ros.ros.parameters import check_parameters
    from cloth_mg_ros.sim.garment_sim import BodySimOptions

    assert check_parameters({"scene": "drape", name: value})[name] == value
    with pytest.raises(ClothInputError, match=name):
        check_parameters({"scene": "drape", name: bad})
    params = load_scene("walking").replace(**{name: value})
    assert getattr(BodySimOptions.from_scene(params, particles=300), name) == value
    assert main(["run", "--scene", sheet, "--particles", "200", "--steps", "3", flag, value,
                 "--out", str(out), "--no-progress"]) == 0
    assert json.loads((out / "summary.json").read_text())[name] == value
