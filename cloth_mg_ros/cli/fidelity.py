"""Command-line pieces of the textile tests: `cloth-mg materials` and the `cloth-mg run`
scenes cantilever, cusick and tensile (called from `cloth_mg_ros.cli.main`)."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.text_table import text_table

FIDELITY_SCENES = ("cantilever", "cusick", "tensile", "swing", "incline", "buckle",
                   "capstan")
# the options of `cloth-mg run` that only textile tests take (add_fidelity_run_args; --seed
# and --angle are shared with other scenes)
TEXTILE_OPTIONS = ("--overhang", "--width", "--orientation", "--axis", "--force", "--direction",
                   "--length", "--shortening", "--gravity", "--amplitude", "--duration",
                   "--short", "--long", "--radius", "--damping-model")


def add_materials_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("materials", help="list the materials: measured fabrics with their "
                                         "sources, and the paper's Table 2 set")
    p.add_argument("--json", default=None, help="also write the list to this JSON file")
    p.add_argument("--notes", action="store_true",
                   help="print how each fabric's figures were derived from its source")


def materials_table() -> list[dict]:
    """One row per material: name, kind, use, SI figures and source."""
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.physics.fabrics import MEASURED
    from cloth_mg_ros.physics.materials import MATERIALS

    records = {rec.name: rec for rec in MEASURED}
    rows = []
    for m in MATERIALS.values():
        rows.append({
            "name": m.name, "kind": m.kind, "use": m.use, "density_kgm2": m.density,
            "bend_nm": m.bend, "bending_length_cm": 100.0 * m.bending_length(),
            "stretch_weft_nm": m.uniaxial_stiffness("weft"),
            "stretch_warp_nm": m.uniaxial_stiffness("warp"),
            "shear_nm": m.shear, "source": m.source, "note": m.note})
        if m.bend_law is not None:
            # By direction: B at curvature 0 and M = k1 kappa + k2 kappa^2 (the model's).
            rows[-1]["bend_directions_nm"] = dict(zip(("weft", "warp", "bias"),
                                                      m.bend_law.k1, strict=True))
            rows[-1]["curvature_law"] = m.bend_law.as_dict()
        if m.name in records:
            rec = records[m.name]
            rows[-1]["bending_moments"] = {
                "curvature_per_m": list(rec.moments("weft")[0]),
                **{d: {"moment_n": list(rec.moments(d)[1]),
                       "fit_k1_nm": rec.curvature_fit(d)[0],
                       "fit_k2_nm2": rec.curvature_fit(d)[1]}
                   for d in ("weft", "warp", "bias")}}
    return rows


def run_materials_command(args: argparse.Namespace) -> int:
    rows = materials_table()
    header = ["material", "kind", "use", "rho kg/m^2", "B N m", "c cm", "E weft N/m",
              "E warp N/m", "shear N/m"]
    print(text_table(header, [[r["name"], r["kind"], r["use"], f"{r['density_kgm2']:.3f}",
                               f"{r['bend_nm']:.3g}", f"{r['bending_length_cm']:.2f}",
                               f"{r['stretch_weft_nm']:.4g}", f"{r['stretch_warp_nm']:.4g}",
                               f"{r['shear_nm']:.4g}"] for r in rows]))
    print("\nB: bending stiffness (mean over directions); c = (B / (rho g))^(1/3): bending "
          "length; E: force per width per strain of a strip pulled with free sides.")
    laws = [r for r in rows if "curvature_law" in r]
    if laws:
        print("\nbending by direction, M = k1 kappa + k2 kappa^2 up to "
              f"{laws[0]['curvature_law']['curvature_cap_per_m']:g} 1/m (physics.bending_law):")
        print(text_table(["material", "k1 weft", "warp", "bias (1e-6 N m)", "k2 weft", "warp",
                          "bias (1e-6 N m^2)"],
                         [[r["name"], *(f"{1e6 * r['curvature_law']['k1_nm'][d]:.2f}"
                                        for d in ("weft", "warp", "bias")),
                           *(f"{1e6 * r['curvature_law']['k2_nm2'][d]:+.3f}"
                             for d in ("weft", "warp", "bias"))] for r in laws]))
    for source in dict.fromkeys(r["source"] for r in rows):
        names = [r["name"] for r in rows if r["source"] == source]
        print(f"\n{', '.join(names)}:\n  {source}")
    if args.notes:
        print()
        for r in rows:
            if r["note"]:
                print(f"{r['name']}: {r['note']}")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(rows, indent=1))
        print(f"\nwrote {args.json}")
    return 0


def add_fidelity_run_args(p: argparse.ArgumentParser) -> None:
    """Options of `cloth-mg run` that only the textile-test scenes take."""
    p.add_argument("--overhang", type=float, default=None,
                   help="cantilever: overhang l beyond the ledge, m")
    p.add_argument("--width", type=float, default=None,
                   help="cantilever / tensile / buckle / capstan / swing: strip width, m "
                        "(default 0.025 / 0.05 / 0.025 / 0.04 / 0.05)")
    p.add_argument("--short", type=float, default=None,
                   help="capstan: the strip's hanging length on its short side, m")
    p.add_argument("--long", type=float, default=None,
                   help="capstan: the strip's hanging length on its long side, m")
    p.add_argument("--radius", type=float, default=None,
                   help="capstan: the cylinder's radius, m (default 0.05)")
    p.add_argument("--orientation", type=float, default=None,
                   help="cantilever / tensile / buckle: angle of the triangulation against the "
                        "strip, degrees (0: edges along it, 45: across)")
    p.add_argument("--seed", type=int, default=None,
                   help="cusick: the start's perturbation; the cantilever's, tensile strip's "
                        "and buckle's garment meshes: the point set")
    p.add_argument("--axis", default=None,
                   help="tensile: pull along the fabric's 'weft' or 'warp'")
    p.add_argument("--force", type=float, default=None, help="tensile: pull, N")
    p.add_argument("--direction", default=None, choices=("weft", "warp", "bias"),
                   help="cantilever: the fabric's axis along the strip (a --material with a "
                        "bending law: that direction's stiffness and curvature law; "
                        "default weft)")
    p.add_argument("--length", type=float, default=None,
                   help="swing: the hanging strip's length L, m (default 0.5); tensile: the "
                        "strip's length, m (default 0.2); buckle: the strip's length between "
                        "its clamps, m")
    p.add_argument("--shortening", type=float, default=None,
                   help="buckle: how far the clamps are brought together, a share of the "
                        "length (0 < S < 1)")
    p.add_argument("--gravity", type=float, default=None,
                   help="buckle: gravity, m/s^2 (default 0: the exact elastica has none)")
    p.add_argument("--amplitude", type=float, default=None,
                   help="swing: the free end's sideways start in the first mode, m "
                        "(default 2 %% of L)")
    p.add_argument("--damping-model", default=None,
                   help="swing / capstan: the fabric's damping force, stiffness (-c H v, the "
                        "default) or strain_rate (on the strain rates alone; needs --linearise "
                        "prediction: sim.newton.DAMPING_MODELS)")
    p.add_argument("--duration", type=float, default=None,
                   help="swing: simulated time, s (default five periods of the exact chain); "
                        "incline: default 0.6; capstan: after the let-go, default 0.5")


# A run in time's options (its steps, its solver's tolerance and levels, its motion): the
# tests that settle by their own rule and solve exactly (cantilever, tensile, Cusick, buckle)
# take none of them
_STEPPING = ("--steps", "--tol", "--levels", "--substeps", "--duration", "--amplitude")


def reject_options(args: argparse.Namespace, scene: str, flags: tuple[str, ...]) -> None:
    """ClothInputError '<flag> is not an option of the <scene> scene' for the first of
    `flags` (as typed: '--spectral-radius') that the command line gave (not None)."""
    for flag in flags:
        if getattr(args, flag.lstrip("-").replace("-", "_"), None) is not None:
            raise ClothInputError(f"{flag} is not an option of the {scene} scene")


def run_fidelity_scene(args: argparse.Namespace) -> int:
    """`cloth-mg run --scene cantilever|cusick|tensile|swing|incline|buckle|capstan`: build,
    settle (or run), measure, write summary.json and a picture in --out."""
    # no textile test has a pose stream, a tick budget or a pull; only the incline a slope,
    # only the capstan hanging lengths and a cylinder, only the scenes in motion Newton
    # iterations and a choice of where to linearise
    reject_options(args, args.scene, ("--rate-hz", "--tick-budget", "--speed", "--travel",
                                      *(() if args.scene == "incline" else ("--angle",)),
                                      *(() if args.scene == "capstan" else
                                        ("--short", "--long", "--radius")),
                                      *(() if args.scene in ("swing", "capstan") else
                                        ("--newton", "--linearise", "--damping-model")),
                                      *(() if args.scene in ("incline", "capstan") else
                                        ("--contact-friction",))))
    out = Path(args.out)
    if args.scene == "cantilever":
        block = _run_cantilever(args, out)
    elif args.scene == "swing":
        block = _run_swing(args, out)
    elif args.scene == "incline":
        block = _run_incline(args, out)
        print(f"  wrote {out / 'summary.json'}")
        return 0 if block["all_converged"] else 1
    elif args.scene == "capstan":
        block = _run_capstan(args, out)
        print(f"  wrote {out / 'summary.json'}")
        return 0 if block["all_converged"] else 1
    elif args.scene == "tensile":
        block = _run_tensile(args, out)
    elif args.scene == "buckle":
        block = _run_buckle(args, out)
    else:
        block = _run_cusick(args, out)
    print(f"  wrote {out / 'summary.json'}")
    return 0 if block.get("settled", False) else 1


def _common_material(args: argparse.Namespace, default: str):
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.physics.materials import get_material

    overrides = {"stretch": args.stretch, "shear": args.shear, "bend": args.bend,
                 "density": args.density}
    return get_material(args.material or default, **overrides)


def _particles(args: argparse.Namespace, default: int) -> int:
    if args.particles is None:
        return default
    try:
        return int(args.particles)
    except ValueError:
        raise ClothInputError(f"--particles must be an integer, got {args.particles!r}") from None


def _tol_option(args: argparse.Namespace) -> dict:
    """{"tol": --tol as a number} when given, else {} (the scene's own default)."""
    if args.tol is None:
        return {}
    try:
        return {"tol": float(args.tol)}
    except ValueError:
        raise ClothInputError(f"--tol must be a number, got {args.tol!r}") from None


def _write(out: Path, summary: dict) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(summary, indent=1))


def _run_cantilever(args: argparse.Namespace, out: Path) -> dict:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.fidelity.cantilever import (
        DEFAULT_PARTICLES,
        DEFAULT_WIDTH,
        CantileverSpec,
        run_cantilever,
    )
    from cloth_mg_ros.fidelity.charts import cantilever_picture

    reject_options(args, "cantilever", ("--axis", "--force", "--obstacle", "--bag", "--garment",
                                        "--dt", *_STEPPING, "--gravity", "--shortening",
                                        "--length"))
    if args.overhang is None:
        raise ClothInputError("the cantilever scene needs --overhang (m)")
    material = _common_material(args, "cotton") if args.material else None
    direction = args.direction or "weft"
    # A measured fabric (unless --bend makes it one stiffness) bends as its law says along
    # the direction cut: the exact elastica takes that direction's k1 and k2.
    k1, k2 = material.direction_bend(direction) if material else (None, 0.0)
    bend = args.bend if args.bend is not None else k1
    cap = material.bend_law.cap if material and material.bend_law else math.inf
    density = args.density if args.density is not None else \
        (material.density if material else None)
    if bend is None or density is None:
        raise ClothInputError("the cantilever scene needs --bend (N m) and --density "
                              "(kg/m^2), or a --material to take them from")
    spec = CantileverSpec(bend, density, args.overhang,
                          DEFAULT_WIDTH if args.width is None else args.width,
                          0.0 if args.orientation is None else args.orientation,
                          args.mesh or "lattice", _particles(args, DEFAULT_PARTICLES),
                          0 if args.seed is None else args.seed, direction, k2, cap)
    block, scene, result = run_cantilever(spec, material, args.solver or "direct")
    _write(out, {"scene": "cantilever", "material": scene.model.material.name,
                 "cantilever": block})
    cantilever_picture(out / "frames.png", [(scene, result.state, block)])
    print(f"cantilever: G = {block['gamma']:.3f}, {block['particles']} particles "
          f"({spec.mesh}, {spec.orientation:g} deg, {spec.direction}), settled "
          f"{block['settled']} after {block['settle']['steps']} steps")
    print(f"  tip {1e3 * block['tip_reach_m']:.2f} mm out, {1e3 * block['tip_drop_m']:.2f} mm "
          f"down (exact {1e3 * block['exact']['tip_reach_m']:.2f}, "
          f"{1e3 * block['exact']['tip_drop_m']:.2f}); chord {block['chord_angle_deg']:.2f} "
          f"deg (exact {block['exact']['chord_angle_deg']:.2f}); error "
          f"{block['tip_error_pct_of_overhang']:.2f} % of l")
    return block


# What the tensile strip and the Cusick drape take from their measured fabric, their own
# settle and their own solve, so that an option for them is refused, not ignored.
_SETTLED_TEST_UNUSED = ("--stretch", "--shear", "--bend", "--density", "--direction",
                        *_STEPPING, "--gravity", "--shortening")


def _run_tensile(args: argparse.Namespace, out: Path) -> dict:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.fidelity.tensile import DEFAULT_PARTICLES, TensileSpec, run_tensile

    reject_options(args, "tensile", ("--overhang", "--obstacle", "--bag", "--garment", "--dt",
                                     *_SETTLED_TEST_UNUSED))
    strip = {k: getattr(args, k) for k in ("length", "width", "seed")
             if getattr(args, k) is not None}
    spec = TensileSpec(args.material or "white-dots-on-blk", args.force, args.axis or "weft",
                       args.mesh or "lattice",
                       0.0 if args.orientation is None else args.orientation,
                       _particles(args, DEFAULT_PARTICLES), **strip)
    block, _, _ = run_tensile(spec, args.solver or "direct")
    _write(out, {"scene": "tensile", "tensile": block})
    print(f"tensile: {spec.material} pulled along its {spec.axis} by {block['force_n']:.4g} N: "
          f"strain {block['strain']:.5f}, F/(kW) {block['expected_strain']:.5f}, error "
          f"{block['error_pct']:+.2f} %")
    return block


def _run_cusick(args: argparse.Namespace, out: Path) -> dict:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.fidelity.cusick import CusickSpec, render_top_view, run_cusick

    reject_options(args, "cusick", ("--overhang", "--width", "--orientation", "--axis",
                                    "--force", "--obstacle", "--bag", "--garment", "--dt",
                                    "--length", "--mesh", *_SETTLED_TEST_UNUSED))
    kwargs = {"material": args.material or "gray-interlock"}
    if args.particles is not None:
        kwargs["particles"] = _particles(args, 0)
    if args.seed is not None:
        kwargs["seed"] = args.seed
    solver = {} if args.solver is None else {"solver_name": args.solver}
    block, scene, result = run_cusick(CusickSpec(**kwargs), **solver)
    _write(out, {"scene": "cusick", "cusick": block})
    render_top_view(out / "frames.png", scene, result.state, block)
    print(f"cusick: {block['material']}, {block['particles']} particles: DC "
          f"{block['dc']:.3f}, {block['nodes']} nodes, settled {block['settled']}")
    return block


def _run_swing(args: argparse.Namespace, out: Path) -> dict:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.fidelity.swing import (
        DEFAULT_DT,
        DEFAULT_LENGTH,
        DEFAULT_MATERIAL,
        DEFAULT_PARTICLES,
        DEFAULT_WIDTH,
        SwingSpec,
        run_swing,
        swing_picture,
    )

    reject_options(args, "swing", ("--overhang", "--orientation", "--axis", "--force",
                                   "--seed", "--obstacle", "--bag", "--garment", "--mesh",
                                   "--stretch", "--shear", "--bend", "--density", "--angle",
                                   "--solver", "--tol", "--levels", "--substeps", "--steps"))
    spec = SwingSpec(args.material or DEFAULT_MATERIAL,
                     DEFAULT_LENGTH if args.length is None else args.length,
                     DEFAULT_WIDTH if args.width is None else args.width,
                     args.amplitude, args.scheme,
                     DEFAULT_DT if args.dt is None else args.dt, args.duration,
                     _particles(args, DEFAULT_PARTICLES),
                     getattr(args, "spectral_radius", None),
                     newton=1 if args.newton is None else args.newton,
                     linearise_at=args.linearise or "start",
                     damping_model=args.damping_model or "stiffness")
    block, _, run = run_swing(spec)
    _write(out, {"scene": "swing", "material": block["material"], "swing": block})
    swing_picture(out / "frames.png", run, block)
    print(f"swing: {block['material']}, L {spec.length:g} m x {spec.width:g} m, "
          f"{block['particles']} particles, {spec.scheme} at dt {spec.dt:.4g} s, "
          f"{block['duration_s']:.2f} s from {1e3 * block['amplitude_m']:.1f} mm")
    print(f"  first mode {block['frequency_hz']:.4f} Hz (exact chain "
          f"{block['exact_frequency_hz']:.4f} Hz, {block['frequency_error_pct']:+.2f} %), "
          f"damping ratio {block['damping_ratio']:.4f} (fabric damping off "
          f"{block['damping_ratio_fabric_off']:.4f}), energy left {block['energy_left']:.3f}")
    return block


def _run_incline(args: argparse.Namespace, out: Path) -> dict:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.fidelity.incline import (
        DEFAULT_DT,
        DEFAULT_DURATION,
        DEFAULT_MATERIAL,
        DEFAULT_PARTICLES,
        InclineSpec,
        incline_picture,
        run_incline,
    )

    reject_options(args, "incline", ("--overhang", "--width", "--orientation", "--axis",
                                     "--force", "--seed", "--obstacle", "--bag", "--garment",
                                     "--mesh", "--length", "--amplitude", "--levels",
                                     "--substeps", "--steps", "--speed", "--travel",
                                     "--stretch", "--shear", "--bend", "--density"))
    if args.angle is None:
        raise ClothInputError("the incline scene needs --angle (the slope, degrees)")
    tol = _tol_option(args)
    spec = InclineSpec(args.friction, args.angle, args.scheme,
                       DEFAULT_DT if args.dt is None else args.dt,
                       DEFAULT_DURATION if args.duration is None else args.duration,
                       _particles(args, DEFAULT_PARTICLES), args.material or DEFAULT_MATERIAL,
                       spectral_radius=args.spectral_radius,
                       **({"solver": args.solver} if args.solver else {}), **tol,
                       contact_friction=args.contact_friction or "projection")
    block, scene, centre = run_incline(spec)
    _write(out, {"scene": "incline", "material": block["material"], "incline": block})
    incline_picture(out / "frames.png", spec, centre, block, scene)
    exact = block["exact_acceleration_mps2"]
    error = "" if block["error_pct"] is None else f", {block['error_pct']:+.3f} %"
    print(f"incline: {spec.angle_deg:g} deg (tan {math.tan(spec.theta):.4f}), friction "
          f"{spec.friction:g}, {block['particles']} particles, {spec.scheme} at dt "
          f"{spec.dt:.4g} s for {spec.duration:g} s")
    print(f"  {'slid' if block['slid'] else 'stuck'}: {1e3 * block['travel_m']:.4g} mm down "
          f"the slope after {block['fit_from_s']:g} s; acceleration "
          f"{block['acceleration_mps2']:.5g} m/s^2 (exact {exact:.5g}{error})")
    return block


def _run_buckle(args: argparse.Namespace, out: Path) -> dict:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.fidelity.buckle import (
        DEFAULT_WIDTH,
        BuckleSpec,
        buckle_picture,
        run_buckle,
    )

    reject_options(args, "buckle", ("--overhang", "--axis", "--force", "--obstacle", "--bag",
                                    "--garment", "--dt", "--direction", *_STEPPING))
    for flag, value in (("--length", args.length), ("--shortening", args.shortening)):
        if value is None:
            raise ClothInputError(f"the buckle scene needs {flag} ("
                                  f"{'m' if flag == '--length' else 'a share of the length'})")
    material = _common_material(args, "cotton") if args.material else None
    bend = args.bend if args.bend is not None else (material.bend if material else None)
    density = args.density if args.density is not None else \
        (material.density if material else None)
    if bend is None:
        raise ClothInputError("the buckle scene needs --bend (N m), or a --material to take "
                              "it from")
    if density is None:
        raise ClothInputError("the buckle scene needs --density (kg/m^2), or a --material to "
                              "take it from")
    spec = BuckleSpec(bend, density, args.length, args.shortening,
                      DEFAULT_WIDTH if args.width is None else args.width,
                      0.0 if args.gravity is None else args.gravity,
                      args.mesh or "lattice",
                      0.0 if args.orientation is None else args.orientation,
                      None if args.particles is None else _particles(args, 0),
                      seed=0 if args.seed is None else args.seed)
    block, scene, run = run_buckle(spec, material, args.solver or "direct")
    _write(out, {"scene": "buckle", "material": scene.model.material.name, "buckle": block})
    buckle_picture(out / "frames.png", scene, run, block)
    print(f"buckle: L {1e3 * spec.length:g} mm x {1e3 * spec.width:g} mm, B {spec.bend:.3g} N m, "
          f"shortened {100 * spec.shortening:g} %, {block['particles']} particles, settled "
          f"{block['settled']} after {block['settle']['steps']} steps")
    print(f"  force {1e3 * block['force_n']:.5g} mN (exact {1e3 * block['exact_force_n']:.5g}, "
          f"{block['force_error_pct']:+.2f} %; onset {1e3 * block['onset_force_n']:.5g}); "
          f"midpoint lift {1e3 * block['lift_m']:.4g} mm (exact "
          f"{1e3 * block['exact_lift_m']:.4g}, {block['lift_error_pct']:+.2f} %)")
    return block


def _run_capstan(args: argparse.Namespace, out: Path) -> dict:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.fidelity.capstan import (
        DEFAULT_DT,
        DEFAULT_DURATION,
        DEFAULT_RADIUS,
        DEFAULT_WIDTH,
        CapstanSpec,
        capstan_picture,
        run_capstan,
    )

    reject_options(args, "capstan", ("--overhang", "--orientation", "--axis", "--force",
                                     "--seed", "--obstacle", "--bag", "--garment", "--mesh",
                                     "--length", "--amplitude", "--levels", "--substeps",
                                     "--steps", "--shortening", "--gravity"))
    for flag, value in (("--short", args.short), ("--long", args.long)):
        if value is None:
            raise ClothInputError(f"the capstan scene needs {flag} (a hanging length, m)")
    material = _common_material(args, "silk") if any(
        v is not None for v in (args.stretch, args.shear, args.bend, args.density)) else None
    tol = _tol_option(args)
    spec = CapstanSpec(args.friction, args.short, args.long,
                       DEFAULT_RADIUS if args.radius is None else args.radius,
                       DEFAULT_WIDTH if args.width is None else args.width,
                       args.material or "silk", args.scheme,
                       DEFAULT_DT if args.dt is None else args.dt,
                       DEFAULT_DURATION if args.duration is None else args.duration,
                       None if args.particles is None else _particles(args, 0),
                       **({"solver": args.solver} if args.solver else {}), **tol,
                       newton=1 if args.newton is None else args.newton,
                       linearise_at=args.linearise or "start",
                       damping_model=args.damping_model or "stiffness",
                       contact_friction=args.contact_friction or "projection")
    block, _scene, times, slide = run_capstan(spec, material)
    _write(out, {"scene": "capstan", "material": block["material"], "capstan": block})
    capstan_picture(out / "frames.png", spec, times, slide, block)
    state = ("off its path" if not block["on_path"] else "held" if block["held"] else "slid")
    print(f"capstan: friction {spec.friction:g}, hanging {spec.short:g} / {spec.long:g} m "
          f"over a {spec.radius:g} m cylinder (holds up to {block['hold_long_m']:.4g} m on the "
          f"long side), {block['particles']} particles, {spec.scheme} at dt {spec.dt:.4g} s")
    print(f"  {state} (exact: {'holds' if block['exact_held'] else 'slides'}); slide "
          f"{1e3 * block['slide_m']:.4g} mm at {block['at_s']:.3g} s (exact "
          f"{1e3 * block['exact_slide_m']:.4g}); farthest off its path "
          f"{1e3 * block['off_path_m']:.3g} mm; meets the exact answer: "
          f"{'yes' if block['meets_exact'] else 'no'}")
    return block
