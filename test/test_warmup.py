"""The warm-up (cloth_mg_ros.apps.warmup): after it, the scene's real tick path compiles or loads
no kernel, and CompileWatch sees what numba compiles."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np

from cloth_mg_ros.apps.warmup import CompileWatch

HERE = Path(__file__).resolve().parent
REPO = HERE.parent


def test_compile_watch_counts_what_numba_compiles_and_nothing_else():
    @numba.njit
    def twice(x):
        return 2 * x

    with CompileWatch() as watch:
        assert twice(3) == 6
        assert twice(4) == 8  # the same signature: no second compilation
        assert twice(np.float64(1.5)) == 3.0  # a new one
    assert watch.count == 2 and all(name.endswith("twice") for name in watch.compiled)
    assert watch.seconds > 0.0
    twice(np.int32(1))  # after stop: not counted
    assert watch.count == 2
    # news: what was compiled since the last call, once
    news = watch.news()
    assert news.startswith("2 kernel(s) compiled") and "twice" in news
    assert watch.news() is None


def test_after_the_warm_up_the_tick_path_needs_no_kernel():
    """In a fresh process (kernels loaded in this one would hide a gap): the walking dress
    at 2400 particles (two levels of detail), warmed up as the node does, then dressed on the
    walk bag and run through it with coalesced ticks, a teleport and level switches: no kernel
    signature is compiled or loaded after the warm-up."""
    run = subprocess.run([sys.executable, str(HERE / "warmup_check.py"), "walking", "2400",
                          str(REPO / "bags" / "walk")], capture_output=True, text=True,
                         cwd=REPO, timeout=600, check=False)
    assert run.returncode == 0, run.stderr
    result = json.loads(run.stdout.strip().splitlines()[-1])
    assert result["levels"] == [0, 1] and result["finite"]
    assert result["compiled_after"] == [] and result["after"] == 0, result
