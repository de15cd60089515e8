"""`cloth-mg batch`: a grid of headless garment runs on recorded motion, as Dask tasks.

    cloth-mg batch --bags walk,run --garments skirt,dress --materials cotton,silk \\
        --particles 600,2400 --solvers mpcg --seconds 2 --out out/batch
    cloth-mg batch --bvh clips/ --garments dress --out out/dataset --scheduler tcp://HOST:8786

The grid is bags x garments x materials x particles x solvers; every other parameter comes
from a base scene (`--scene`, default walking: floor, self-contact, tolerance, the step rule).
Each run replays its bag from the first valid pose (dressing there) through the lead-in and
`seconds` of motion after it, exactly as `cloth-mg run` does (`runner.run_body_scene`, one
tick per pose message, one thread), and writes its own folder under `out`:

    <bag>-<garment>-<material>-<particles>-<solver>/
        summary.json     per-tick figures and the options used
        positions.npz    the garment after every tick ("positions" (k, n, 3) float32 m,
                         "stamps" (k,) s, "faces", "final" float64), compressed
        frames.png       a strip of frames
        markers/         with --mcap: the ticks as visualization_msgs/Marker (MCAP)

and one row of `out/manifest.csv` (MANIFEST_COLUMNS): the grid's values, `status` ok or
failed, `error`, `wall_s`, `ticks`, `max_penetration_m`, `median_tick_ms`, `particles_simulated`
and `output` (the folder, relative to `out`). A run is written into `<folder>.partial` and
renamed when it is complete, so a folder without the suffix is a whole run.

Bag paths and `out` must be reachable from every worker under the same names (on a cluster: a
shared file system); `out` is made absolute first.

Resuming: a second call with the same `out` runs only what is not `ok` in the manifest (with
its folder present); failed runs are tried again. A run that raises becomes a `failed` row
with its error and never stops the others; a run whose worker is lost is retried by Dask
(`cluster.RETRIES`). `--bvh DIR` converts every DIR/*.bvh into `out/bags/<stem>` first (as
tasks; a bag already there is kept) and adds those bags to the grid.
"""

from __future__ import annotations

import csv
import os
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cloth_mg_ros.apps.cluster import run_tasks
from cloth_mg_ros.config.scenes import is_body_scene, load_scene
from cloth_mg_ros.config.schema import MAX_PARTICLES
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import bundled_bag, read_pose_frames, resolve_bag, write_marker_bag
from cloth_mg_ros.io.text_table import text_table
from cloth_mg_ros.mesh.garments import GARMENTS
from cloth_mg_ros.mesh.garments.design import MIN_PARTICLES
from cloth_mg_ros.motion.pose_bags import bag_from_bvh
from cloth_mg_ros.physics.materials import MATERIALS
from cloth_mg_ros.solvers import validate_solver_name

__all__ = ["MANIFEST_COLUMNS", "BatchGrid", "RunSpec", "format_batch_report", "read_manifest",
           "run_batch", "run_one", "validate_grid"]

MANIFEST = "manifest.csv"
MANIFEST_COLUMNS = ("bag", "garment", "material", "particles", "solver", "status", "error",
                    "wall_s", "ticks", "max_penetration_m", "median_tick_ms",
                    "particles_simulated", "output")
PARTIAL = ".partial"


@dataclass(frozen=True)
class RunSpec:
    """One run of the grid: a bag (bundled name or path), garment, material, particles,
    solver."""

    bag: str
    garment: str
    material: str
    particles: int
    solver: str

    @property
    def key(self) -> tuple[str, str, str, int, str]:
        return (self.bag, self.garment, self.material, self.particles, self.solver)

    @property
    def folder(self) -> str:
        """The run's folder name under the batch's output (the bag's name for a path)."""
        stem = Path(self.bag).name if os.sep in self.bag or "/" in self.bag else self.bag
        safe = "".join(c if c.isalnum() or c in "._" else "_" for c in stem) or "bag"
        return f"{safe}-{self.garment}-{self.material}-{self.particles}-{self.solver}"


@dataclass
class BatchGrid:
    """The grid and what every run shares: seconds of motion after the lead-in (None: the
    whole bag), the base scene, whether to write the markers as MCAP."""

    bags: list[str]
    garments: list[str] = field(default_factory=lambda: ["dress"])
    materials: list[str] = field(default_factory=lambda: ["white-dots-on-blk"])
    particles: list[int] = field(default_factory=lambda: [1200])
    solvers: list[str] = field(default_factory=lambda: ["mpcg"])
    seconds: float | None = None
    scene: str = "walking"
    mcap: bool = False

    def runs(self) -> list[RunSpec]:
        """Every run, bags outermost (a bag's runs finish together)."""
        return [RunSpec(b, g, m, int(n), s) for b in self.bags for g in self.garments
                for m in self.materials for n in self.particles for s in self.solvers]


def validate_grid(grid: BatchGrid) -> None:
    """Check every value of the grid before anything runs; ClothInputError names the first
    problem (an unknown garment, material or solver, a bag that is neither a bundled name nor
    a path, a bad particle count or duration)."""
    for name, values in (("--bags", grid.bags), ("--garments", grid.garments),
                         ("--materials", grid.materials), ("--particles", grid.particles),
                         ("--solvers", grid.solvers)):
        if not values:
            raise ClothInputError(f"{name} is empty")
        if len(set(values)) != len(values):
            raise ClothInputError(f"{name} lists a value twice: {values}")
    for bag in grid.bags:
        if not (Path(bag).exists() or ("/" not in bag and bundled_bag(bag).exists())):
            raise ClothInputError(f"--bags: {bag!r} is neither a bag path nor a bundled bag "
                                  f"(walk, brisk_walk, run, jump)")
    for g in grid.garments:
        if g not in GARMENTS:
            raise ClothInputError(f"--garments: unknown garment {g!r} (one of "
                                  f"{', '.join(GARMENTS)})")
    for m in grid.materials:
        if m not in MATERIALS:
            raise ClothInputError(f"--materials: unknown material {m!r} (one of "
                                  f"{', '.join(MATERIALS)})")
    # the garments' own smallest meshes: a count below one fails every run of it
    low = max(MIN_PARTICLES[g] for g in grid.garments)
    for n in grid.particles:
        if isinstance(n, bool) or not isinstance(n, int) or not low <= n <= MAX_PARTICLES:
            raise ClothInputError(f"--particles must be integers in {low}..{MAX_PARTICLES} "
                                  f"(the smallest of --garments {','.join(grid.garments)}: "
                                  f"{low}), got {n!r}")
    for s in grid.solvers:
        validate_solver_name(s)
    if grid.seconds is not None and not (isinstance(grid.seconds, (int, float))
                                         and 0.0 < grid.seconds < 1e6):
        raise ClothInputError(f"--seconds must be a positive number, got {grid.seconds!r}")
    if not is_body_scene(grid.scene):
        raise ClothInputError(f"--scene {grid.scene!r} is not a body scene (walking, "
                              f"brisk_walking, running, jumping or a params .yaml)")
    try:  # a missing or bad scene file would fail every run on the workers
        load_scene(grid.scene)
    except ClothInputError as exc:
        raise ClothInputError(f"--scene: {exc}") from None


# -- one run, on a worker ---------------------------------------------------------------
def messages_for(frames: list, seconds: float | None) -> int | None:
    """How many pose messages after the first make the lead-in (the first pose held still)
    plus `seconds` of motion; None: all of them."""
    if seconds is None or not frames:
        return None
    first = frames[0][1]
    still = next((k for k, (_, p) in enumerate(frames)
                  if p.shape != first.shape or abs(p - first).max() > 1e-9), len(frames)) - 1
    start = frames[max(still, 0)][0]
    return next((k for k, (t, _) in enumerate(frames) if t - start > seconds + 1e-9),
                len(frames)) - 1


def run_one(task: tuple[RunSpec, str, str, float | None, bool]) -> dict:
    """One run (spec, batch output folder, base scene, seconds, mcap) on this process; returns
    its manifest row. Never raises for the run's own failures: they are the row's error."""
    spec, out_root, scene, seconds, mcap = task
    t0 = time.perf_counter()
    folder = Path(out_root) / spec.folder
    partial = folder.with_name(folder.name + PARTIAL)
    row = {"bag": spec.bag, "garment": spec.garment, "material": spec.material,
           "particles": spec.particles, "solver": spec.solver, "output": spec.folder}
    try:
        summary = _simulate(spec, scene, seconds, mcap, partial)
        if folder.exists():
            shutil.rmtree(folder)
        partial.rename(folder)
    except Exception as exc:  # noqa: BLE001 - the run's failure is its row, not the batch's
        shutil.rmtree(partial, ignore_errors=True)
        return {**row, "status": "failed", "error": f"{type(exc).__name__}: {exc}",
                "wall_s": round(time.perf_counter() - t0, 3), "output": ""}
    return {**row, "status": "ok", "error": "", "wall_s": round(time.perf_counter() - t0, 3),
            "ticks": len(summary["ticks"]),
            "max_penetration_m": summary["max_penetration"],
            "median_tick_ms": summary["median_total_ms"],
            "particles_simulated": summary["particles"]}


def _simulate(spec: RunSpec, scene: str, seconds: float | None, mcap: bool,
              out: Path) -> dict:
    """The run itself into folder `out`; returns runner.run_body_scene's summary."""
    # imported here: matplotlib (charts), loaded only when needed
    from cloth_mg_ros.apps.runner import run_body_scene

    if out.exists():
        shutil.rmtree(out)
    params = load_scene(scene).replace(
        bag=str(resolve_bag(spec.bag)), garment=spec.garment, material=spec.material,
        particles=spec.particles, solver=spec.solver, threads=1)  # one worker per core
    steps = messages_for(read_pose_frames(params.bag, params.topic), seconds)
    summary = run_body_scene(params, out, steps=steps, progress=False)
    if mcap:
        with np.load(out / "positions.npz") as data:
            write_marker_bag(out / "markers", data["stamps"], data["positions"],
                             data["faces"])
    return summary


def convert_bvh(task: tuple[str, str]) -> str:
    """BVH file -> bag folder (kept when it exists already); returns the bag's path."""
    bvh, out = task
    if (Path(out) / "metadata.yaml").is_file():
        return out
    partial = out + PARTIAL
    shutil.rmtree(partial, ignore_errors=True)
    bag_from_bvh(bvh, partial)
    os.replace(partial, out)
    return out


# -- the manifest -----------------------------------------------------------------------
def read_manifest(out: str | Path) -> dict[tuple, dict]:
    """The rows of out/manifest.csv by run key (empty when there is none)."""
    path = Path(out) / MANIFEST
    if not path.is_file():
        return {}
    with path.open(newline="") as f:
        reader = csv.DictReader(f)
        rows = list(reader)
        missing = set(MANIFEST_COLUMNS) - set(reader.fieldnames or ())
    if missing:
        raise ClothInputError(f"{path}: not a batch manifest (no column {min(missing)})")
    return {(r["bag"], r["garment"], r["material"], int(r["particles"]), r["solver"]): r
            for r in rows}


def _write_manifest(out: Path, rows: list[dict]) -> None:
    """Rewrite out/manifest.csv whole (a temporary file renamed over it)."""
    tmp = out / (MANIFEST + ".tmp")
    with tmp.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=MANIFEST_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: ("" if row.get(k) is None else row.get(k))
                             for k in MANIFEST_COLUMNS})
    os.replace(tmp, out / MANIFEST)


def _finished(out: Path, row: dict | None) -> bool:
    return bool(row) and row.get("status") == "ok" and bool(row.get("output")) and (
        out / row["output"] / "summary.json").is_file()


# -- the driver -------------------------------------------------------------------------
def run_batch(grid: BatchGrid, out: str | Path, client, bvh_dir: str | Path | None = None,
              log: Callable[[str], None] = print, progress: bool = True) -> dict:
    """Run the grid on the Dask `client` (cluster.dask_client) into `out`; see the module
    docstring. Returns {"rows": every row in grid order, "ran": runs done now, "skipped":
    runs finished before, "failed": rows that failed now}."""
    out = Path(out).resolve()  # the workers' working folder need not be this one
    out.mkdir(parents=True, exist_ok=True)
    if bvh_dir is not None:
        grid.bags = list(grid.bags) + _convert_clips(Path(bvh_dir), out, client, log,
                                                      progress)
    validate_grid(grid)
    known = read_manifest(out)
    runs = grid.runs()
    todo = [r for r in runs if not _finished(out, known.get(r.key))]
    skipped = len(runs) - len(todo)
    log(f"batch: {len(runs)} runs ({skipped} finished before, {len(todo)} to run) into {out}")
    rows = dict(known)
    failed = []
    tasks = [(spec, str(out), grid.scene, grid.seconds, grid.mcap) for spec in todo]
    for task, row, error in run_tasks(client, run_one, tasks, desc="batch",
                                      progress=progress):
        spec = task[0]
        if error is not None:  # the task itself was lost (its worker died every retry)
            row = {"bag": spec.bag, "garment": spec.garment, "material": spec.material,
                   "particles": spec.particles, "solver": spec.solver, "status": "failed",
                   "error": f"task lost: {type(error).__name__}: {error}", "output": ""}
        if row["status"] != "ok":
            failed.append(row)
            log(f"batch: {spec.folder} failed: {row['error']}")
        rows[spec.key] = row
        _write_manifest(out, _ordered(rows, runs))
    ordered = _ordered(rows, runs)
    _write_manifest(out, ordered)
    in_grid = {spec.key for spec in runs}
    return {"rows": [r for r in ordered if _key(r) in in_grid], "ran": len(todo),
            "skipped": skipped, "failed": failed}


def _key(row: dict) -> tuple:
    return (row["bag"], row["garment"], row["material"], int(row["particles"]), row["solver"])


def _ordered(rows: dict[tuple, dict], runs: Sequence[RunSpec]) -> list[dict]:
    """The grid's rows in grid order, then rows of earlier grids in the same folder."""
    order = {spec.key: k for k, spec in enumerate(runs)}
    return sorted(rows.values(), key=lambda r: (order.get(_key(r), len(order)), _key(r)))


def _convert_clips(bvh_dir: Path, out: Path, client, log, progress: bool) -> list[str]:
    """Every bvh_dir/*.bvh as a bag under out/bags (tasks); returns the bags' paths."""
    clips = sorted(bvh_dir.glob("*.bvh"))
    if not clips:
        raise ClothInputError(f"--bvh {bvh_dir}: no .bvh files there")
    (out / "bags").mkdir(parents=True, exist_ok=True)
    tasks = [(str(c), str(out / "bags" / c.stem)) for c in clips]
    bags = {}
    for task, path, error in run_tasks(client, convert_bvh, tasks, desc="bvh -> bag",
                                       progress=progress):
        if error is not None:
            raise ClothInputError(f"--bvh {task[0]}: {error}")
        bags[task[1]] = path
    log(f"batch: {len(bags)} clip(s) of {bvh_dir} as bags in {out / 'bags'}")
    return [bags[t[1]] for t in tasks]


def format_batch_report(result: dict) -> str:
    """The final table: one line per run of the grid, then the counts."""
    rows = result["rows"]
    body = [[Path(r["bag"]).name, r["garment"], r["material"], str(r["particles"]),
             r["solver"], r["status"], _fmt(r.get("median_tick_ms"), ".1f"),
             _fmt(r.get("max_penetration_m"), ".2e"), _fmt(r.get("wall_s"), ".1f"),
             r.get("output") or r.get("error", "")[:60]] for r in rows]
    text = text_table(["bag", "garment", "material", "particles", "solver", "status",
                  "ms/tick", "max pen. m", "wall s", "output / error"], body)
    ok = sum(r["status"] == "ok" for r in rows)
    return (f"{text}\n{ok} ok, {len(rows) - ok} failed ({result['ran']} run now, "
            f"{result['skipped']} finished before)")


def _fmt(value, spec: str) -> str:
    try:
        return format(float(value), spec)
    except (TypeError, ValueError):
        return "-"
