"""`cloth-mg bench capstan`: Coulomb friction on a curved surface against the capstan's exact
answer (`fidelity.capstan`), and the spinning tube (`fidelity.spin`), which tells how much of
what the capstan shows is the integrator's damping of rotation.

A grid of runs: for each friction coefficient, strips whose long side is a set share of the
longest that holds (below 1 it must hold, above it must slide at the exact rate), and a
frictionless strip 1.5 times as long on one side as on the other, each at every step size.
Each row: whether the strip stayed on its path over the cylinder (a strip that wraps round,
falls through or swings off it measures nothing), whether it held, and its slide against
the exact one. Then free tubes spinning at several rim speeds, of two fabrics, at every step
size: the share of their angular momentum left after 0.1 s (exact: all of it). Each run at
every count of Newton iterations and linearisation point asked for. Prints two tables and
writes a JSON of every run.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

from cloth_mg_ros.bench.results import git_output, write_json
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.text_table import text_table

DEFAULT_JSON = "doc/results/bench_capstan.json"
FRICTIONS = (0.2, 0.5, 0.8)
LOAD_RATIOS = (0.8, 0.95, 1.05, 1.25)
FRICTIONLESS_RATIO = 1.5  # long over short hanging length of the frictionless strip
STEPS_PER_S = (60, 240)
QUICK = {"frictions": (0.5,), "ratios": (0.8, 1.25), "steps_per_s": (60,),
         "spin_speeds": (0.1,), "spin_materials": ("silk",), "spin_steps_per_s": (60,),
         "newton": (1,), "linearise": ("start",), "damping": ("stiffness",)}
SHORT = 0.2  # m, the short side's hanging length
SPIN_SPEEDS = (0.01, 0.1, 1.0)  # m/s, the tube's rim
SPIN_MATERIALS = ("silk", "gray-interlock")  # the stiffest membrane and a soft knit
SPIN_STEPS_PER_S = (60, 240, 960)
NEWTON = (1, 3)  # Newton iterations per step (sim.newton): the node's one, and three
LINEARISE = ("start", "prediction")  # where a step linearises (sim.schemes.LINEARISE_AT)
DAMPING = ("stiffness", "strain_rate")  # the fabric's damping (sim.newton.DAMPING_MODELS)


def cases(frictions: tuple[float, ...], ratios: tuple[float, ...]) -> list[tuple[float, float]]:
    """(mu, long / hold length) of each row: the frictionless strip first."""
    return [(0.0, FRICTIONLESS_RATIO)] + [(mu, r) for mu in frictions for r in ratios]


def bench_capstan(frictions: tuple[float, ...] = FRICTIONS,
                  ratios: tuple[float, ...] = LOAD_RATIOS,
                  steps_per_s: tuple[int, ...] = STEPS_PER_S, material: str | None = None,
                  log=print, spin: dict | None = None,
                  newton: tuple[int, ...] = NEWTON,
                  linearise: tuple[str, ...] = LINEARISE,
                  damping: tuple[str, ...] = DAMPING) -> dict:
    """Run every case at every step size, count of Newton iterations, linearisation point
    and damping model (strain_rate at the prediction only), and the spinning tubes
    (``spin``: {"speeds", "materials", "steps_per_s"}, default the module's; {} for none):
    {"meta", "runs": [capstan blocks], "spins": [spin results]}."""
    # imported here: the simulator (numba kernels) loads when the bench runs
    from cloth_mg_ros.fidelity.capstan import (
        DEFAULT_MATERIAL,
        DEFAULT_RADIUS,
        CapstanSpec,
        contact_radius,
        hold_length,
        run_capstan,
    )

    _check_axes(frictions, ratios, steps_per_s, newton, linearise, damping)
    variants = _variants(linearise, newton, damping)
    t0 = time.perf_counter()
    runs = []
    for mu, ratio in cases(frictions, ratios):
        hold = hold_length(SHORT, mu, contact_radius(DEFAULT_RADIUS))
        long = ratio * (SHORT if mu == 0.0 else hold)
        for f in steps_per_s:
            for lin, k, dm in variants:
                spec = CapstanSpec(mu, SHORT, long, dt=1.0 / f,
                                   material=material or DEFAULT_MATERIAL, newton=k,
                                   linearise_at=lin, damping_model=dm)
                block, *_ = run_capstan(spec)
                block["steps_per_s"] = f
                runs.append(block)
                log(_row_line(block))
    spins = spin_runs(**({"speeds": SPIN_SPEEDS, "materials": SPIN_MATERIALS,
                          "steps_per_s": SPIN_STEPS_PER_S} if spin is None else spin),
                      variants=variants, log=log) if spin != {} else []
    meta = {"machine": platform.node(), "cpus": os.cpu_count(),
            "platform": platform.platform(), "commit": git_output("rev-parse", "--short", "HEAD"),
            "changed_files": git_output("status", "--porcelain", "-uno"),
            "threads": {k: os.environ.get(k, "unset")
                        for k in ("OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS")},
            "short_m": SHORT, "wall_s": time.perf_counter() - t0}
    return {"meta": meta, "runs": runs, "spins": spins}


def _check_axes(frictions, ratios, steps_per_s, newton, linearise, damping) -> None:
    """ClothInputError naming the first bad value of `bench_capstan`'s axes."""
    for mu in frictions:
        if not mu > 0.0:
            raise ClothInputError(f"--frictions must be positive (the frictionless strip is "
                                  f"always run), got {mu}")
    for r in ratios:
        if not r > 0.0:
            raise ClothInputError(f"--ratios must be positive, got {r}")
    for f in steps_per_s:
        if f < 1:
            raise ClothInputError(f"--steps-per-s must be positive integers, got {f}")
    for k in newton:
        if k < 1:
            raise ClothInputError(f"--newton must be positive integers, got {k}")
    for lin in linearise:
        if lin not in LINEARISE:
            raise ClothInputError(f"--linearise must list {' or '.join(LINEARISE)}, got "
                                  f"{lin!r}")
    for dm in damping:
        if dm not in DAMPING:
            raise ClothInputError(f"--damping-models must list {' or '.join(DAMPING)}, got "
                                  f"{dm!r}")


def _variants(linearise: tuple[str, ...], newton: tuple[int, ...], damping: tuple[str, ...]
              ) -> list[tuple[str, int, str]]:
    """(linearisation point, Newton iterations, damping model) of each run of a case: the
    strain-rate damping at the prediction only (sim.newton.check_damping_model)."""
    return [(lin, k, dm) for lin in linearise for k in newton for dm in damping
            if dm == "stiffness" or lin == "prediction"]


def spin_runs(speeds: tuple[float, ...] = (), materials: tuple[str, ...] = (),
              steps_per_s: tuple[int, ...] = (),
              variants: tuple[tuple[str, int, str], ...] = (("start", 1, "stiffness"),),
              log=print) -> list[dict]:
    """A free tube spun at each rim speed, of each fabric, at each step size and variant
    (linearisation point, Newton iterations, damping model: `_variants`;
    `fidelity.spin.run_spin`)."""
    # imported here: the simulator (numba kernels) loads when the bench runs
    from cloth_mg_ros.fidelity.spin import SpinSpec, run_spin

    out = []
    for material in materials:
        for speed in speeds:
            for f in steps_per_s:
                for lin, k, dm in variants:
                    result = run_spin(SpinSpec(speed, material, dt=1.0 / f, newton=k,
                                               linearise_at=lin, damping_model=dm))
                    result["steps_per_s"] = f
                    out.append(result)
                    log(f"spin {material} {speed:g} m/s 1/{f} s, {_step_name(result)}: "
                        f"{result['kept']:.3f} of the angular momentum left after "
                        f"{result['duration_s']:g} s")
    return out


def _step_name(b: dict) -> str:
    """How a run's steps were taken: 'prediction, 1, strain_rate' (linearised at, Newton
    iterations, damping model)."""
    return (f"{b.get('linearise_at', 'start')}, {b['newton']}, "
            f"{b.get('damping_model', 'stiffness')}")


def _cells(b: dict) -> list[str]:
    exact = "holds" if b["exact_held"] else "slides"
    if not b["on_path"]:
        got = f"off its path ({1e3 * b['off_path_m']:.0f} mm)"
    else:
        got = "holds" if b["held"] else "slides"
    slide = f"{1e3 * b['slide_m']:.1f}" if b["on_path"] else "-"
    return [f"{b['friction']:g}", f"{b['load_ratio']:.2f}", f"1/{b['steps_per_s']}",
            _step_name(b), exact, got, slide,
            f"{1e3 * b['exact_slide_m']:.1f}", f"{b['at_s']:.2f}"]


HEADER = ["mu", "long / hold", "dt s", "linearised at, Newton, damping", "exact", "measured",
          "slide mm", "exact slide mm", "at s"]


def _row_line(b: dict) -> str:
    return "  ".join(f"{h} {c}" for h, c in zip(HEADER, _cells(b), strict=True))


def format_report(result: dict) -> str:
    """The runs as a text table, and how many met the exact answer."""
    from cloth_mg_ros.fidelity.capstan import SLIDE_TOLERANCE_PCT

    rows = [_cells(b) for b in result["runs"]]
    met = sum(1 for b in result["runs"] if b["meets_exact"])
    text = (text_table(HEADER, rows) + f"\n{met} of {len(rows)} runs meet the exact answer "
            f"(on the cylinder; holding where it holds, else sliding within "
            f"{SLIDE_TOLERANCE_PCT:g} % of its slide)")
    spins = result.get("spins", [])
    if spins:
        steps = sorted({s["steps_per_s"] for s in spins})
        keys = sorted({(s["material"], s["speed_mps"], _step_name(s)) for s in spins})
        kept = {(s["material"], s["speed_mps"], _step_name(s), s["steps_per_s"]): s["kept"]
                for s in spins}
        table = [[m, f"{v:g}", how,
                  *(f"{kept[(m, v, how, f)]:.3f}" if (m, v, how, f) in kept else "-"
                    for f in steps)] for m, v, how in keys]
        text += ("\n\nA free tube spinning about its axis: the share of its angular momentum "
                 "left after 0.1 s (exact: 1)\n"
                 + text_table(["fabric", "rim m/s", "linearised at, Newton, damping",
                               *(f"1/{f} s" for f in steps)], table))
    return text


def add_cli(bsub: argparse._SubParsersAction) -> None:
    """Register `cloth-mg bench capstan` on the bench sub-parsers."""
    p = bsub.add_parser("capstan", help="friction on a curved surface: a strip over a rough "
                        "cylinder against the capstan's exact holding load and slide")
    p.add_argument("--frictions", default=",".join(f"{m:g}" for m in FRICTIONS),
                   help="Coulomb coefficients, comma-separated (a frictionless strip is always "
                        "run too)")
    p.add_argument("--ratios", default=",".join(f"{r:g}" for r in LOAD_RATIOS),
                   help="the long side's hanging length over the longest that holds, "
                        "comma-separated")
    p.add_argument("--steps-per-s", default=",".join(str(f) for f in STEPS_PER_S),
                   help="step sizes as steps per second, comma-separated")
    p.add_argument("--material", default=None, help="the strip's fabric (default silk)")
    p.add_argument("--newton", default=",".join(str(k) for k in NEWTON),
                   help="Newton iterations per step, comma-separated (sim.newton; 1: the "
                        "node's step)")
    p.add_argument("--linearise", default=",".join(LINEARISE),
                   help="where each step linearises the forces, comma-separated: start (the "
                        "node's default) and prediction (sim.newton.predicted_step)")
    p.add_argument("--damping-models", default=",".join(DAMPING),
                   help="the fabric's damping force, comma-separated: stiffness (-c H v) and "
                        "strain_rate (on the strain rates alone; at the prediction only)")
    p.add_argument("--quick", action="store_true",
                   help="one coefficient (0.5), two loads (0.8, 1.25), 1/60 s, one Newton "
                        "iteration from the start; one spinning tube (silk, 0.1 m/s)")
    p.add_argument("--json", default=DEFAULT_JSON, help=f"JSON output (default {DEFAULT_JSON})")
    p.set_defaults(bench_func=run_cli)


def run_cli(args: argparse.Namespace) -> int:
    """Run the bench from parsed options; exit 0."""
    from cloth_mg_ros.bench.solvers import parse_list

    spin = None
    if args.quick:
        frictions, ratios, steps = QUICK["frictions"], QUICK["ratios"], QUICK["steps_per_s"]
        spin = {"speeds": QUICK["spin_speeds"], "materials": QUICK["spin_materials"],
                "steps_per_s": QUICK["spin_steps_per_s"]}
        newton, linearise, damping = QUICK["newton"], QUICK["linearise"], QUICK["damping"]
    else:
        frictions = tuple(parse_list(args.frictions, "frictions", float))
        ratios = tuple(parse_list(args.ratios, "ratios", float))
        steps = tuple(parse_list(args.steps_per_s, "steps-per-s", int))
        newton = tuple(parse_list(args.newton, "newton", int))
        linearise = tuple(parse_list(args.linearise, "linearise", str))
        damping = tuple(parse_list(args.damping_models, "damping-models", str))
    result = bench_capstan(frictions, ratios, steps, args.material, spin=spin, newton=newton,
                           linearise=linearise, damping=damping)
    print(format_report(result))
    write_json(args.json, result)
    print(f"wrote {args.json}")
    return 0
