"""`cloth-mg bench matvec`: Algorithm 1 against scipy CSR and BSR products on one matrix.

The matrix is a real step system: the drape scene's sheet after it has fallen onto the
sphere (stretched, bent, with contacts), assembled once. Every method multiplies the same
vectors; each is timed over ``repeat`` products in batches and the median per product is
reported. The products are timed with every loaded OpenBLAS on one thread (bench.blas_threads;
``blas_threads`` records the count in effect).
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from cloth_mg_ros.bench.blas_threads import blas_thread_count, one_blas_thread
from cloth_mg_ros.bench.results import write_json
from cloth_mg_ros.config.schema import MAX_PARTICLES
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.generators import MIN_PARTICLES
from cloth_mg_ros.physics.materials import MATERIALS, get_material
from cloth_mg_ros.physics.system import bs_full_matvec, bs_matvec
from cloth_mg_ros.sim.integrator import assemble_step
from cloth_mg_ros.sim.sheets import build_scene
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.solvers import PCGSolver

BATCH = 5


def bench_system(particles: int, material: str = "cotton", settle_steps: int = 30):
    """A drape-scene step system at ~particles, after ``settle_steps`` explicit-free steps of
    falling (loose solves: only the matrix matters here)."""
    scene = build_scene("drape", particles, get_material(material))
    sim = Simulator(scene.model, scene.state, PCGSolver(tol=1e-2, maxiter=200), dt=1 / 60)
    for _ in range(settle_steps):
        sim.step()
    return assemble_step(scene.model, sim.state, sim.dt, "bdf2").system


def validate_matvec_args(particles: int, material: str, repeat: int) -> None:
    """Check the options before any work; one ClothInputError names every bad one."""
    problems = []
    if isinstance(particles, bool) or not isinstance(particles, int) or not (
            MIN_PARTICLES <= particles <= MAX_PARTICLES):
        problems.append(f"--particles must be an integer in [{MIN_PARTICLES}, {MAX_PARTICLES}], "
                        f"got {particles!r}")
    if str(material).strip().lower() not in MATERIALS:
        problems.append(f"--material: unknown material {material!r} (choose from "
                        f"{', '.join(MATERIALS)})")
    if isinstance(repeat, bool) or not isinstance(repeat, int) or repeat < BATCH:
        problems.append(f"--repeat must be an integer >= {BATCH} (the products are timed in "
                        f"batches of {BATCH}), got {repeat!r}")
    if problems:
        raise ClothInputError("bench matvec: " + "; ".join(problems))


def _median_ms(fn, repeat: int) -> float:
    """Median wall time of one call of fn, ms, over repeat // BATCH batches of BATCH calls
    (after one untimed call)."""
    fn()  # warm-up (numba compile, caches)
    times = []
    for _ in range(repeat // BATCH):
        t0 = time.perf_counter()
        for _ in range(BATCH):
            fn()
        times.append((time.perf_counter() - t0) / BATCH)
    return 1e3 * float(np.median(times))


def bench_matvec(particles: int = 20000, material: str = "cotton", repeat: int = 200) -> dict:
    """Time the products of the drape-step matrix of about `particles` particles with an
    (n, 3) vector, each over `repeat` products (>= BATCH); returns the figures as a dict (also
    what --json writes), ms per product. ClothInputError for a bad option, before any work."""
    validate_matvec_args(particles, material, repeat)
    material = str(material).strip().lower()
    system = bench_system(particles, material)
    n = system.n
    rng = np.random.default_rng(0)
    d = rng.standard_normal((n, 3))
    d_flat = d.reshape(-1)
    full_diag = system.full_diagonal()
    csr = system.to_csr()
    bsr = system.to_bsr()
    reference = csr @ d_flat

    # Every method allocates its result each call, as scipy's `A @ x` does (it has no output
    # argument): the numba products write into a fresh array, so that allocation is timed in
    # all four alike. Their return value is that array.
    def alg1():
        res = np.empty((n, 3))
        bs_matvec(system.diag, system.pairs, system.offd, d, res)
        return res

    def alg2():
        res = np.empty((n, 3))
        bs_full_matvec(full_diag, system.pairs, system.offd, d, res)
        return res

    methods = {
        "algorithm1": alg1,
        "standard_block_numba": alg2,
        "scipy_csr": lambda: csr @ d_flat,
        "scipy_bsr": lambda: bsr @ d_flat,
    }
    errors = {}
    for name, fn in methods.items():
        res = fn().reshape(-1)
        errors[name] = float(np.linalg.norm(res - reference) / np.linalg.norm(reference))
    with one_blas_thread():  # whatever the environment says: comparable with our kernels
        ms = {name: _median_ms(fn, repeat) for name, fn in methods.items()}
        blas = blas_thread_count()
    best_scipy = min(ms["scipy_csr"], ms["scipy_bsr"])
    return {
        "particles": int(n),
        "pairs": len(system.pairs),
        "nnz_csr": int(csr.nnz),
        "material": material,
        "repeat": repeat,
        "ms_per_product": ms,
        "rel_error_vs_csr": errors,
        "speedup_vs_best_scipy": best_scipy / ms["algorithm1"],
        "speedup_vs_csr": ms["scipy_csr"] / ms["algorithm1"],
        "speedup_vs_bsr": ms["scipy_bsr"] / ms["algorithm1"],
        "speedup_vs_standard_block": ms["standard_block_numba"] / ms["algorithm1"],
        "openblas_threads": os.environ.get("OPENBLAS_NUM_THREADS", "unset"),
        "blas_threads": blas,
        "machine": platform.processor() or platform.machine(),
    }


def print_matvec(result: dict) -> None:
    print(f"matvec on a drape-step system: {result['particles']} particles, "
          f"{result['pairs']} pair blocks, CSR nnz {result['nnz_csr']}")
    for name, ms in result["ms_per_product"].items():
        print(f"  {name:22s} {ms:8.3f} ms/product  (rel. diff vs CSR "
              f"{result['rel_error_vs_csr'][name]:.1e})")
    print(f"  Algorithm 1 speed-up: {result['speedup_vs_best_scipy']:.2f}x over the best scipy "
          f"product, {result['speedup_vs_standard_block']:.2f}x over the standard block "
          f"product (paper: ~1.3x)")


def add_cli(bsub: argparse._SubParsersAction) -> None:
    """Register `cloth-mg bench matvec` on the bench sub-parsers."""
    m = bsub.add_parser("matvec", help="Algorithm 1 against scipy CSR and BSR products")
    m.add_argument("--particles", type=int, default=20000)
    m.add_argument("--material", default="cotton")
    m.add_argument("--repeat", type=int, default=200,
                   help=f"timed products per method (at least {BATCH}, in batches of {BATCH})")
    m.add_argument("--json", default=None, help="write the figures to this JSON file")
    m.set_defaults(bench_func=run_cli)


def run_cli(args: argparse.Namespace) -> int:
    """Time the products, print them, write the JSON (with --json)."""
    result = bench_matvec(args.particles, args.material, args.repeat)
    print_matvec(result)
    if args.json:
        write_json(args.json, result)
        print(f"wrote {args.json}")
    return 0
