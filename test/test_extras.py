"""The node's install without the extras (`pip install cloth_mg_ros`): the node, the runner
and the cost model import and run without matplotlib, pillow, pyamg or Dask, and a command
that needs one of them names the extra to install. Checked in a subprocess where those
modules cannot be imported, as on a lean install."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.extras import EXTRAS, extra_of, missing_extra_message, require_extra

REPO = Path(__file__).resolve().parent.parent

# a finder first on sys.meta_path that refuses every module of an extra
BLOCK = textwrap.dedent(f"""
    import sys

    class _Lean:
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in {sorted(EXTRAS)!r}:
                raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
            return None

    sys.meta_path.insert(0, _Lean())
""")


def _lean(code: str, tmp_path: Path) -> subprocess.CompletedProcess:
    script = tmp_path / "lean.py"
    script.write_text(BLOCK + textwrap.dedent(code))
    return subprocess.run([sys.executable, str(script)], cwd=REPO, capture_output=True,
                          text=True, timeout=600, check=False)


def test_the_node_and_a_headless_walk_need_no_extra(tmp_path):
    out = tmp_path / "walk"
    run = _lean(f"""
        import cloth_mg_ros.ros.node, cloth_mg_ros.ros.session, cloth_mg_ros.budget.cost_model
        import cloth_mg_ros.ros.managed_node, cloth_mg_ros.ros.body_input
        import cloth_mg_ros.ros.body_topic, cloth_mg_ros.ros.grasp_services
        from cloth_mg_ros.cli.main import main

        rc = main(["run", "--scene", "walking", "--particles", "300", "--tol", "1e-3",
                   "--steps", "3", "--no-progress", "--out", {str(out)!r}])
        loaded = sorted(m for m in sys.modules if m.split(".")[0] in {sorted(EXTRAS)!r})
        print("RESULT", rc, loaded)
    """, tmp_path)
    assert "RESULT 0 []" in run.stdout, run.stdout + run.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["ticks"]) == 3 and (out / "positions.npz").is_file()
    assert not (out / "frames.png").exists()
    assert "frames.png not drawn" in run.stderr
    assert "pip install 'cloth_mg_ros[bench]'" in run.stderr


def test_a_command_that_needs_an_extra_names_it_before_any_work(tmp_path):
    run = _lean(f"""
        from cloth_mg_ros.cli.main import main
        from cloth_mg_ros.errors import ClothInputError
        from cloth_mg_ros.solvers import make_solver

        print("BENCH", main(["bench", "matvec", "--particles", "600"]))
        print("BATCH", main(["batch", "--bags", "walk", "--out", {str(tmp_path / "b")!r}]))
        try:
            make_solver("amg")
        except ClothInputError as exc:
            print("AMG", exc)
    """, tmp_path)
    assert "BENCH 2" in run.stdout and "BATCH 2" in run.stdout, run.stdout + run.stderr
    assert ("cloth-mg bench matvec needs distributed, matplotlib, PIL, pyamg and threadpoolctl, "
            "which the 'bench' extra installs: pip install 'cloth_mg_ros[bench]'") in run.stderr
    assert ("cloth-mg batch needs distributed, which the 'cluster' extra installs: "
            "pip install 'cloth_mg_ros[cluster]'") in run.stderr
    assert "AMG solver 'amg' needs pyamg, which the 'bench' extra installs" in run.stdout


def test_extras_are_named_by_their_top_level_module():
    assert extra_of("matplotlib.pyplot") == "bench" and extra_of("distributed") == "cluster"
    assert extra_of("numpy") is None and extra_of(None) is None
    assert missing_extra_message("PIL.Image", "x") == (
        "x needs PIL, which the 'bench' extra installs: pip install 'cloth_mg_ros[bench]'")
    require_extra("numpy", "anything")  # installed: no error
    with pytest.raises(ClothInputError, match="no_such_module"):
        require_extra("no_such_module_xyz", "y")
