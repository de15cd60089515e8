"""`cloth-mg bench fidelity`: the simulator against the textile tests' exact answers.

Three tables, one run:

* cantilever (ASTM D1388): the tip of a settled strip against the exact heavy elastica for
  G = rho g l^3 / B from 1 to 50, on the aligned lattice, the lattice turned 45 degrees and
  the garments' kind of isotropic mesh, at the default resolution; and the error against
  resolution (three resolutions) at G = 8 (the standard's 41.5 degree chord); and every
  measured fabric cut along its weft, warp and bias (physics.bending_law), its overhang
  set for G = 8 with that direction's k1, against the elastica of that direction's moment
  law M = k1 kappa + k2 kappa^2;
* tensile: a strip pulled by a known force, strain against F / (k W), along the weft and
  the warp, on the three meshes;
* Cusick drape (BS 5058): every measured fabric from five slightly perturbed starts (DC and
  node count, mean and spread: the test's own repeatability), DC against resolution for
  two fabrics, DC against bending length (the textile literature reports a monotone rise).

Writes the figures to JSON and the charts beside it (PNG).
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

from scipy.stats import spearmanr

from cloth_mg_ros.bench.results import write_json
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.fidelity.cantilever import (
    DEFAULT_PARTICLES,
    DIRECTIONS,
    CantileverSpec,
    centre_profile,
    run_cantilever,
)
from cloth_mg_ros.fidelity.charts import cantilever_profiles_chart, chart_pyplot, drape_chart
from cloth_mg_ros.fidelity.cusick import CusickSpec, run_cusick, summarise_repeats
from cloth_mg_ros.fidelity.elastica import GRAVITY
from cloth_mg_ros.fidelity.tensile import TENSILE_AXES, TensileSpec, run_tensile
from cloth_mg_ros.io.text_table import text_table
from cloth_mg_ros.physics.materials import MATERIALS, MEASURED_MATERIALS, get_material

DEFAULT_JSON = "doc/results/bench_fidelity.json"
GAMMAS = (1.0, 2.0, 4.0, 8.0, 16.0, 30.0, 50.0)
MESHES = (("lattice", 0.0), ("lattice", 45.0), ("garment", 0.0))
CANTILEVER_OVERHANG = 0.1  # m
CANTILEVER_DENSITY = 0.2  # kg/m^2
RESOLUTION_GAMMA = 8.0
TENSILE_MATERIALS = ("cotton", "11oz-black-denim", "tango-red-jet-set", "gray-interlock")
CUSICK_RESOLUTION_FABRICS = ("gray-interlock", "royal-target")


def add_cli(bsub: argparse._SubParsersAction) -> None:
    """Register `cloth-mg bench fidelity` on the bench sub-parsers."""
    p = bsub.add_parser("fidelity", help="the cantilever against the exact elastica, the "
                        "tensile strip against F/(kW), the Cusick drape of every measured "
                        "fabric: tables, JSON and charts")
    p.add_argument("--quick", action="store_true",
                   help="fewer cases: G 1, 8, 50; two fabrics, two starts; for a smoke run")
    p.add_argument("--fabrics", default="measured",
                   help="comma list of materials for the Cusick table (default: every "
                        "measured fabric)")
    p.add_argument("--seeds", type=int, default=5,
                   help="perturbed starts per fabric in the Cusick table (default 5)")
    p.add_argument("--json", default=DEFAULT_JSON, help=f"JSON output (default {DEFAULT_JSON})")
    p.set_defaults(bench_func=run_cli)


def fabric_names(text: str) -> list[str]:
    names = list(MEASURED_MATERIALS) if text == "measured" else \
        [t.strip().lower() for t in text.split(",") if t.strip()]
    bad = [n for n in names if n not in MATERIALS]
    if bad or not names:
        raise ClothInputError(f"--fabrics: unknown material(s) {bad or text!r} (choose from "
                              f"{', '.join(MATERIALS)})")
    return names


def cantilever_rows(gammas: tuple[float, ...], meshes: tuple, particles: int | None = None
                    ) -> tuple[list[dict], list[dict]]:
    """(rows, profiles): one settled cantilever per (G, mesh). Lengths in m; the profile is
    the strip's centre line in units of l."""
    rows, profiles = [], []
    for mesh, orientation in meshes:
        for gamma in gammas:
            bend = CANTILEVER_DENSITY * GRAVITY * CANTILEVER_OVERHANG ** 3 / gamma
            spec = CantileverSpec(bend, CANTILEVER_DENSITY, CANTILEVER_OVERHANG,
                                  orientation=orientation, mesh=mesh,
                                  particles=particles or DEFAULT_PARTICLES)
            t0 = time.perf_counter()
            block, scene, result = run_cantilever(spec)
            block["wall_s"] = time.perf_counter() - t0
            rows.append(block)
            profiles.append({"gamma": gamma, "mesh": mesh, "orientation_deg": orientation,
                             "particles": block["particles"],
                             "label": f"G {gamma:g}, {mesh} {orientation:g} deg: "
                                      f"{block['tip_error_pct_of_overhang']:.2f} % of l",
                             "profile": (centre_profile(scene, result.state)
                                         / spec.overhang).tolist()})
    return rows, profiles


def direction_rows(fabrics: list[str], particles: int = DEFAULT_PARTICLES,
                   gamma: float = RESOLUTION_GAMMA) -> list[dict]:
    """One settled cantilever per (measured fabric, direction): the fabric's own membrane
    and bending law, the overhang giving G = gamma with that direction's k1 (m)."""
    rows = []
    for name in fabrics:
        mat = get_material(name)
        for direction in DIRECTIONS:
            k1, _ = mat.direction_bend(direction)
            overhang = (gamma * k1 / (mat.density * GRAVITY)) ** (1.0 / 3.0)
            spec = CantileverSpec.of_material(mat, direction, overhang, particles=particles)
            block, scene, result = run_cantilever(spec, mat)
            x = result.state.x[scene.tip]
            # The tip's tilt across the strip: a bias strip of an unbalanced fabric twists.
            tilt = math.degrees(math.atan2(float(x[:, 2].max() - x[:, 2].min()),
                                           float(x[:, 1].max() - x[:, 1].min())))
            block.update({"material": name, "tip_tilt_deg": tilt})
            rows.append(block)
            print(f"  {name} {direction}: error {block['tip_error_pct_of_overhang']:.2f} % of l",
                  flush=True)
    return rows


def _print_directions(rows: list[dict]) -> None:
    print("\ncantilever by direction (G = 8 with the direction's k1; exact: the elastica of "
          "its M = k1 kappa + k2 kappa^2)")
    print(text_table(["material", "direction", "k1 N m", "k2 N m^2", "l mm", "error % of l",
                      "tip tilt deg", "settled"],
                     [[r["material"], r["direction"], f"{r['bend_nm']:.3g}",
                       f"{r['bend_k2_nm2']:+.3g}", f"{1e3 * r['overhang_m']:.1f}",
                       f"{r['tip_error_pct_of_overhang']:.2f}", f"{r['tip_tilt_deg']:.2f}",
                       str(r["settled"])] for r in rows]))


def _print_cantilever(rows: list[dict], title: str) -> None:
    print(title)
    print(text_table(["G", "mesh", "particles", "chord deg", "exact", "tip error % l",
                      "settled", "steps", "s"],
                     [[f"{r['gamma']:g}", f"{r['mesh']} {r['orientation_deg']:g}",
                       str(r["particles"]), f"{r['chord_angle_deg']:.2f}",
                       f"{r['exact']['chord_angle_deg']:.2f}",
                       f"{r['tip_error_pct_of_overhang']:.2f}", str(r["settled"]),
                       str(r["settle"]["steps"]), f"{r['wall_s']:.1f}"] for r in rows]))


def tensile_rows(materials: tuple[str, ...], meshes: tuple) -> list[dict]:
    """One settled tensile strip per (material, axis, mesh)."""
    rows = []
    for name in materials:
        for axis in TENSILE_AXES:
            for mesh, orientation in meshes:
                block, _, _ = run_tensile(TensileSpec(name, axis=axis, mesh=mesh,
                                                      orientation=orientation))
                block.update({"material": name, "axis": axis, "mesh": mesh,
                              "orientation_deg": orientation})
                rows.append(block)
    return rows


def cusick_rows(fabrics: list[str], seeds: int, particles: int | None = None) -> list[dict]:
    """Every fabric from ``seeds`` perturbed starts: the blocks of `fidelity.cusick`."""
    rows = []
    for name in fabrics:
        for seed in range(seeds):
            kwargs = {"material": name, "seed": seed}
            if particles is not None:
                kwargs["particles"] = particles
            t0 = time.perf_counter()
            block, _, _ = run_cusick(CusickSpec(**kwargs))
            block["wall_s"] = time.perf_counter() - t0
            block.pop("outline_r_m", None)
            rows.append(block)
    return rows


def summarise_cusick(rows: list[dict]) -> list[dict]:
    """Per fabric: `fidelity.cusick.summarise_repeats` of its starts, with its bending
    length, stiffness and density."""
    out = []
    for name in dict.fromkeys(r["material"] for r in rows):
        mat = get_material(name)
        out.append({"material": name, "bending_length_cm": 100.0 * mat.bending_length(),
                    "bend_nm": mat.bend, "density_kgm2": mat.density,
                    **summarise_repeats([r for r in rows if r["material"] == name])})
    return out


def spearman(x: list[float], y: list[float]) -> float:
    """Rank correlation of x and y (scipy.stats.spearmanr)."""
    return float(spearmanr(x, y).statistic) if len(x) > 2 else math.nan


def run_cli(args: argparse.Namespace) -> int:
    if args.seeds < 1:
        raise ClothInputError(f"--seeds must be at least 1, got {args.seeds}")
    fabrics = fabric_names(args.fabrics)
    gammas = (1.0, 8.0, 50.0) if args.quick else GAMMAS
    if args.quick and args.fabrics == "measured":
        fabrics = fabrics[:2]
    seeds = min(args.seeds, 2) if args.quick else args.seeds
    t_start = time.perf_counter()

    cant, profiles, res_rows = _cantilever_tables(gammas)
    measured = list(MEASURED_MATERIALS)[:2] if args.quick else list(MEASURED_MATERIALS)
    directions = direction_rows(measured)
    _print_directions(directions)
    tens = _tensile_table(TENSILE_MATERIALS[:2] if args.quick else TENSILE_MATERIALS)
    cusick = _cusick_tables(fabrics, seeds, args.quick)
    out = Path(args.json)
    result = {
        "cantilever": {"overhang_m": CANTILEVER_OVERHANG, "density_kgm2": CANTILEVER_DENSITY,
                       "rows": cant, "resolution": res_rows,
                       "max_tip_error_pct": max(r["tip_error_pct_of_overhang"] for r in cant),
                       "directions": directions},
        "tensile": {"rows": tens, "max_abs_error_pct": max(abs(r["error_pct"]) for r in tens)},
        "cusick": cusick,
        "wall_s": time.perf_counter() - t_start,
    }
    write_json(out, result)
    charts = [cantilever_profiles_chart(out.with_name(out.stem + "_cantilever.png"),
                                        [p for p in profiles if p["mesh"] == "lattice"
                                         and p["orientation_deg"] == 45.0]),
              drape_chart(out.with_name(out.stem + "_drape.png"), cusick["fabrics"]),
              resolution_chart(out.with_name(out.stem + "_resolution.png"), res_rows)]
    print(f"\nwrote {out} and {', '.join(str(c) for c in charts)} in "
          f"{result['wall_s']:.0f} s")
    return 0


def _cantilever_tables(gammas: tuple[float, ...]) -> tuple[list[dict], list[dict], list[dict]]:
    """(rows, profiles) at the default resolution and the rows against resolution at
    RESOLUTION_GAMMA, both printed."""
    cant, profiles = cantilever_rows(gammas, MESHES)
    _print_cantilever(cant, f"cantilever: tip against the exact heavy elastica, l "
                            f"{CANTILEVER_OVERHANG} m, default resolution")
    resolutions = (DEFAULT_PARTICLES // 2, DEFAULT_PARTICLES, DEFAULT_PARTICLES * 2)
    res_rows = []
    for particles in resolutions:
        res_rows += cantilever_rows((RESOLUTION_GAMMA,), MESHES, particles)[0]
    _print_cantilever(res_rows, f"\ncantilever at G = {RESOLUTION_GAMMA:g} against resolution")
    return cant, profiles, res_rows


def _tensile_table(materials: tuple[str, ...]) -> list[dict]:
    """The tensile rows of `materials`, printed."""
    tens = tensile_rows(materials, MESHES)
    print("\ntensile strip: strain against F / (k W)")
    print(text_table(["material", "axis", "mesh", "k N/m", "F/(kW)", "strain", "error %"],
                     [[r["material"], r["axis"], f"{r['mesh']} {r['orientation_deg']:g}",
                       f"{r['stiffness_n_per_m']:.4g}", f"{r['expected_strain']:.5f}",
                       f"{r['strain']:.5f}", f"{r['error_pct']:+.3f}"] for r in tens]))
    return tens


def _cusick_tables(fabrics: list[str], seeds: int, quick: bool) -> dict:
    """The result's "cusick": every fabric from `seeds` starts, DC against bending length,
    and DC against resolution (one fabric when quick), printed."""
    drape = cusick_rows(fabrics, seeds)
    summary = summarise_cusick(drape)
    print(f"\nCusick drape, {seeds} perturbed starts per fabric")
    print(text_table(["fabric", "c cm", "DC mean", "DC range", "nodes", "modal", "settled"],
                     [[s["material"], f"{s['bending_length_cm']:.2f}", f"{s['dc_mean']:.3f}",
                       f"{s['dc_min']:.3f}-{s['dc_max']:.3f}",
                       ",".join(map(str, s["nodes"])), str(s["node_mode"]),
                       str(s["all_settled"])] for s in summary]))
    rho = spearman([s["bending_length_cm"] for s in summary], [s["dc_mean"] for s in summary])
    print("DC against bending length: Spearman rank correlation "
          + (f"{rho:+.2f}" if math.isfinite(rho) else "n/a (fewer than three fabrics)"))
    rho = rho if math.isfinite(rho) else None
    base = CusickSpec(material=fabrics[0]).particles
    conv_fabrics = [f for f in CUSICK_RESOLUTION_FABRICS if f in fabrics] or fabrics[:1]
    conv = []
    for name in conv_fabrics[:1] if quick else conv_fabrics:
        for particles in (base // 2, base, base * 2):
            row = cusick_rows([name], 1, particles)[0]
            conv.append(row)
    print("\nCusick DC against resolution (seed 0)")
    print(text_table(["fabric", "particles", "DC", "nodes"],
                     [[r["material"], str(r["particles"]), f"{r['dc']:.3f}", str(r["nodes"])]
                      for r in conv]))
    converged = {}
    for name in dict.fromkeys(r["material"] for r in conv):
        dcs = [r["dc"] for r in conv if r["material"] == name]
        converged[name] = bool(abs(dcs[-1] - dcs[-2]) <= 0.02)
        print(f"  {name}: the two finest differ by {abs(dcs[-1] - dcs[-2]):.3f} "
              f"({'converged' if converged[name] else 'not converged'} at 0.02)")
    return {"runs": drape, "fabrics": summary, "resolution": conv,
            "resolution_converged": converged, "dc_vs_bending_length_spearman": rho,
            "published_dc": "no published measured drape coefficient of these ten "
                            "fabrics was found (shared/REFERENCES.md)"}


def resolution_chart(path: Path, rows: list[dict]) -> Path:
    """Tip error against particles, one line per mesh kind."""
    plt = chart_pyplot()
    fig, ax = plt.subplots(figsize=(5.6, 4.0))
    for mesh, orientation in MESHES:
        mine = [r for r in rows if r["mesh"] == mesh and r["orientation_deg"] == orientation]
        ax.plot([r["particles"] for r in mine], [r["tip_error_pct_of_overhang"] for r in mine],
                "o-", label=f"{mesh} {orientation:g} deg")
    ax.set_xscale("log")
    ax.set_xlabel("particles")
    ax.set_ylabel("tip error, % of overhang")
    ax.set_title(f"cantilever at G = {RESOLUTION_GAMMA:g}: error against resolution")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
