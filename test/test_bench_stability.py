"""`cloth-mg bench stability` and the explicit integrator it contrasts with: the outcome
rules on synthetic figures, symplectic Euler's free fall and stability bound, option checks,
and one tiny map through the CLI."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from matplotlib import pyplot as plt

from cloth_mg_ros.bench.stability import (
    EXPLICIT_SCHEME,
    MAX_PENETRATION,
    MAX_SPECIFIC_KINETIC,
    MAX_SPEED,
    OUTCOMES,
    CellWatch,
    classify,
    dt_label,
    map_columns,
    motion_window,
    parse_dt,
    summarise,
    validate_stability_args,
)
from cloth_mg_ros.cli.main import main
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.generators import sheet_hierarchy
from cloth_mg_ros.physics.materials import Material, get_material
from cloth_mg_ros.sim.explicit import ExplicitSimulator, critical_step
from cloth_mg_ros.sim.model import GRAVITY, ClothState, build_model
from cloth_mg_ros.sim.schemes import DEFAULT_SPECTRAL_RADIUS
from cloth_mg_ros.sim.sheets import build_scene
from cloth_mg_ros.sim.tick_stats import TickStats

# Benchmark tests: `colcon test` skips them (pytest.ini); `make test` runs them.
pytestmark = pytest.mark.bench

SOFT = Material("soft", stretch=20.0, shear=10.0, bend=1e-6)


# -- outcomes -----------------------------------------------------------------------------
def test_classify_each_outcome_and_severity():
    calm = {"failures": 0, "finite": True, "max_speed": 3.0, "specific_kinetic": 1.0,
            "max_penetration": 0.0, "converged": True}
    assert classify(**calm) == "ok"
    assert classify(**{**calm, "converged": False}) == "not_converged"
    assert classify(**{**calm, "max_penetration": 1.01 * MAX_PENETRATION}) == "tunnelled"
    assert classify(**{**calm, "max_penetration": MAX_PENETRATION}) == "ok"  # bound included
    assert classify(**{**calm, "max_speed": 1.01 * MAX_SPEED}) == "blew_up"
    assert classify(**{**calm, "specific_kinetic": 1.01 * MAX_SPECIFIC_KINETIC}) == "blew_up"
    assert classify(**{**calm, "max_speed": float("nan")}) == "blew_up"
    # A motion played 3x faster moves the body 3x faster: the bounds follow it.
    assert classify(**{**calm, "max_speed": 2.9 * MAX_SPEED}, speed_up=3) == "ok"
    assert classify(**{**calm, "max_speed": 3.01 * MAX_SPEED}, speed_up=3) == "blew_up"
    assert classify(**{**calm, "specific_kinetic": 8.9 * MAX_SPECIFIC_KINETIC},
                    speed_up=3) == "ok"
    assert classify(**{**calm, "specific_kinetic": 9.01 * MAX_SPECIFIC_KINETIC},
                    speed_up=3) == "blew_up"
    assert classify(**{**calm, "failures": 1}) == "nan"
    assert classify(**{**calm, "finite": False}) == "nan"
    # The most severe applies: nan > blew_up > tunnelled > not_converged.
    worst = {"failures": 2, "finite": True, "max_speed": 1e9, "specific_kinetic": 1e9,
             "max_penetration": 1.0, "converged": False}
    assert classify(**worst) == "nan"
    assert classify(**{**worst, "failures": 0}) == "blew_up"
    assert classify(**{**worst, "failures": 0, "max_speed": 1.0,
                       "specific_kinetic": 1.0}) == "tunnelled"
    assert OUTCOMES == ("ok", "not_converged", "tunnelled", "blew_up", "nan")


def _tick(converged=True, penetration=0.0, kinetic=0.1, iterations=20, substeps=2):
    return TickStats(0.0, 10.0, 5.0, iterations, 1e-5, converged, penetration, 0, substeps,
                     kinetic)


def test_cell_watch_keeps_the_worst_and_when():
    watch = CellWatch(mass=0.2)
    v = np.zeros((4, 3))
    assert watch.add(_tick(), v, True, 0, 0.1) == "ok"
    assert watch.add(_tick(converged=False, iterations=1000), v, True, 0, 0.2) == \
        "not_converged"
    # a later converged message does not undo it
    assert watch.add(_tick(), v, True, 0, 0.3) == "not_converged"
    assert watch.add(_tick(penetration=0.05), v, True, 0, 0.4) == "tunnelled"
    assert not watch.fatal
    fast = np.zeros((4, 3))
    fast[2] = [0.0, 30.0, 0.0]
    assert watch.add(_tick(), fast, True, 0, 0.5) == "blew_up" and watch.fatal
    figs = watch.figures()
    assert figs["max_speed"] == pytest.approx(30.0)
    assert figs["max_penetration"] == pytest.approx(0.05)
    assert figs["iterations_median"] == pytest.approx(10.0)  # 20 its / 2 substeps
    assert figs["iterations_max"] == pytest.approx(500.0)
    assert figs["unconverged_messages"] == 1 and figs["messages"] == 5 and figs["steps"] == 10
    assert figs["outcome_at_s"] == pytest.approx(0.5)
    json.dumps(figs)
    # kinetic energy per kg of garment past its bound
    heavy = CellWatch(mass=0.2)
    assert heavy.add(_tick(kinetic=1.01 * MAX_SPECIFIC_KINETIC * 0.2), v, True, 0, 0.1) \
        == "blew_up"
    # non-finite: a dropped step or non-finite positions, and the figure stays JSON-safe
    dropped = CellWatch(mass=0.2)
    assert dropped.add(_tick(), v, True, 1, 0.1) == "nan" and dropped.fatal
    inf = CellWatch(mass=0.2)
    assert inf.add(_tick(), np.full((4, 3), np.inf), False, 0, 0.1) == "nan"
    json.dumps(inf.figures())


def test_summary_counts_and_mg_verdict():
    cells = [{"solver": "mg", "outcome": "ok"}, {"solver": "pcg", "outcome": "nan"},
             {"solver": "mg", "outcome": "ok"}, {"solver": "pcg", "outcome": "ok"}]
    s = summarise(cells, ["pcg", "mg"])
    assert s["counts"]["pcg"] == {"ok": 1, "not_converged": 0, "tunnelled": 0, "blew_up": 0,
                                  "nan": 1}
    assert s["mg_ok_everywhere"] is True
    cells.append({"solver": "mg", "outcome": "tunnelled"})
    assert summarise(cells, ["pcg", "mg"])["mg_ok_everywhere"] is False
    assert summarise(cells[1:2], ["pcg"])["mg_ok_everywhere"] is None
    # cells of a map before the scheme axis are BDF2's
    assert summarise(cells, ["pcg", "mg"])["by_scheme"]["bdf2"]["mg"]["tunnelled"] == 1


def test_summary_counts_per_scheme_and_the_explicit_solver_once():
    cells = [{"solver": s, "scheme": sc, "outcome": o} for sc, s, o in (
        ("euler", "mg", "ok"), ("genalpha", "mg", "blew_up"), ("euler", "pcg", "ok"),
        ("genalpha", "pcg", "nan"), ("genalpha", "mg", "ok"), (EXPLICIT_SCHEME, "explicit",
                                                                "blew_up"))]
    s = summarise(cells, ["pcg", "mg", "explicit"], ["euler", "genalpha"])
    assert set(s["by_scheme"]) == {"euler", "genalpha", EXPLICIT_SCHEME}
    assert s["by_scheme"]["genalpha"]["mg"] == {"ok": 1, "not_converged": 0, "tunnelled": 0,
                                                "blew_up": 1, "nan": 0}
    assert s["by_scheme"]["euler"]["mg"]["ok"] == 1 and s["by_scheme"]["euler"]["pcg"]["ok"] == 1
    assert s["by_scheme"]["genalpha"]["pcg"]["nan"] == 1
    assert list(s["by_scheme"][EXPLICIT_SCHEME]) == ["explicit"]  # once, not per scheme
    assert s["by_scheme"][EXPLICIT_SCHEME]["explicit"]["blew_up"] == 1
    assert s["counts"]["mg"]["ok"] == 2 and s["counts"]["mg"]["blew_up"] == 1  # all schemes
    assert s["mg_ok_by_scheme"] == {"euler": True, "genalpha": False}
    assert s["mg_ok_everywhere"] is False
    assert map_columns(["pcg", "explicit", "mg"], ["euler", "genalpha"]) == [
        ("euler", "pcg"), ("euler", "mg"), ("genalpha", "pcg"), ("genalpha", "mg"),
        (EXPLICIT_SCHEME, "explicit")]


def test_motion_window_skips_the_still_lead_in():
    still = np.zeros((16, 7))
    still[:, 6] = 1.0
    frames = []
    for k in range(90):  # 30 Hz: 1 s still, then moving
        p = still.copy()
        t = k / 30.0
        if t > 1.0 - 1e-9:
            p[:, 0] = 0.5 * (t - 0.9667)
        frames.append((t, p))
    dress, first, end = motion_window(frames, 1.0)
    assert first == 30  # the first pose that differs
    assert frames[first - 1][0] - frames[dress][0] == pytest.approx(0.5)  # SETTLE_S
    assert frames[end - 1][0] - frames[first - 1][0] == pytest.approx(1.0)
    assert motion_window(frames, 9.0)[2] == len(frames)  # the clip ends first


def test_faster_motion_keeps_the_lead_in_and_the_pace():
    from cloth_mg_ros.bench.stability import faster

    still = np.zeros((2, 7))
    frames = [(k / 30, still) for k in range(3)]  # a still lead-in
    frames += [(k / 30, still + k) for k in range(3, 10)]  # then moving
    out = faster(frames, 2)
    assert out[:3] == frames[:3]
    assert [p[0, 0] for _, p in out[3:]] == [4.0, 6.0, 8.0]  # every second moving pose
    assert np.allclose(np.diff([s for s, _ in out]), 1 / 30)  # still one per 1/30 s
    assert faster(frames, 1) is frames
    # Asked for 0.3 s of motion (9 messages), the 3-message sped-up clip (from the last still
    # pose 0 to 8) swings back to its start and forth again: 4 6 8 | 6 4 0 | 4 6 8.
    out = faster(frames, 2, seconds=0.3)
    assert [p[0, 0] for _, p in out[3:]] == [4.0, 6.0, 8.0, 6.0, 4.0, 0.0, 4.0, 6.0, 8.0]
    assert np.allclose(np.diff([s for s, _ in out]), 1 / 30)
    with pytest.raises(ClothInputError, match="--speeds"):
        validate_stability_args("cotton", "1/30", "walk", "mg", 500, 1.0, 1, speeds="0,3")


def test_steps_parse_and_label():
    assert parse_dt("1/240") == pytest.approx(1 / 240)
    assert parse_dt("0.01") == 0.01 and parse_dt(0.5) == 0.5
    for bad in ("1/0", "-1/60", "abc", "nan", "0", True):
        assert parse_dt(bad) is None
    assert dt_label(1 / 120) == "1/120" and dt_label(0.003) == "0.003"


# -- the explicit integrator --------------------------------------------------------------
def test_explicit_free_fall_is_symplectic_euler_exactly():
    """No drag, no pins, no colliders: a rigidly falling sheet has no internal force, so
    v_n = n h g and x_n = x_0 + h^2 g n (n + 1) / 2 (symplectic Euler), to rounding."""
    hier = sheet_hierarchy(120, None, 1.0, 1.0, plane="xy", centre=(0.0, 0.0, 2.0))
    mat = Material("still air", 20.0, 10.0, 1e-6, air_drag=0.0)
    model = build_model(hier.levels[0], mat)
    x0 = np.array(hier.levels[0].rest)
    # Within the stability bound, or rounding noise in the internal forces would grow.
    h, steps = 0.5 * critical_step(model), 40
    sim = ExplicitSimulator(model, ClothState.at_rest(x0), dt=h)
    assert sim.scheme == "symplectic_euler" and sim.solver is None
    for _ in range(steps):
        stats = sim.step()
    n = steps
    np.testing.assert_allclose(sim.state.v, np.broadcast_to(n * h * GRAVITY, x0.shape),
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(sim.state.x, x0 + h * h * GRAVITY * n * (n + 1) / 2.0,
                               rtol=0, atol=1e-12)
    assert sim.state.t == pytest.approx(n * h)
    assert stats.converged and stats.iterations == 0
    mass = model.mass.sum()
    assert stats.kinetic_energy == pytest.approx(0.5 * mass * (n * h * 9.81) ** 2, rel=1e-9)


def _run_explicit(material, dt_factor, steps):
    scene = build_scene("hang", 200, material)
    model = scene.model
    dt = dt_factor * critical_step(model)
    sim = ExplicitSimulator(model, scene.state, dt=dt)
    pins = model.pinned
    top = scene.state.x[pins].copy()
    speed = 0.0
    with np.errstate(all="ignore"):
        for _ in range(steps):
            sim.step()
            speed = float(np.nanmax(np.linalg.norm(sim.state.v, axis=1)))
            if not speed < 1e3:
                break
    return sim, speed, top, dt


def test_explicit_stable_below_its_bound_unstable_above():
    """A soft sheet hanging by two corners: stable at half the damped stability bound (for a
    sizeable stretch of time), blowing up at twice it; the pins stay put."""
    sim, speed, top, _ = _run_explicit(SOFT, 0.5, 800)
    assert np.all(np.isfinite(sim.state.x))
    assert speed < 3.0  # a 1 m sheet falling about 1 s at most
    assert sim.state.t > 0.5
    np.testing.assert_array_equal(sim.state.x[sim.model.pinned], top)
    # the sheet fell and hangs below its pins
    assert sim.state.x[:, 2].min() < top[:, 2].min() - 0.1
    _, fast, _, _ = _run_explicit(SOFT, 2.0, 300)
    assert not fast < 1e3


def test_explicit_bound_for_the_bundled_fabrics():
    """Every bundled fabric needs explicit steps of microseconds at these sizes, far below
    the 1/240 s the stability map starts at (which is the point of the contrast)."""
    for name in ("silk", "cotton", "leather"):
        scene = build_scene("hang", 200, get_material(name))
        assert critical_step(scene.model) < 1e-4


def test_explicit_rejects_bad_step():
    scene = build_scene("hang", 100, SOFT)
    with pytest.raises(ClothInputError):
        ExplicitSimulator(scene.model, scene.state, dt=0.0)


# -- options ------------------------------------------------------------------------------
def test_validation_names_every_bad_value(tmp_path):
    with pytest.raises(ClothInputError) as err:
        validate_stability_args("cotton,felt,cotton", "1/240,1/7,abc", "walk,swim",
                                "mg,nope,explicit", "12", "-1", "0", json_path=str(tmp_path))
    msg = str(err.value)
    for part in ("felt", "1/7", "abc", "swim", "nope", "--particles", "--seconds", "--workers",
                 "--json", "twice"):
        assert part in msg, part
    cfg = validate_stability_args("Cotton", "1/60, 0.03333333", "run", "mg,explicit", "500",
                                  "1.5", "2")
    assert cfg.materials == ["cotton"] and cfg.motions == ["run"]
    assert cfg.dts == [pytest.approx(1 / 60), pytest.approx(1 / 30)]
    assert cfg.particles == [500] and cfg.seconds == 1.5 and cfg.jobs == 2
    with pytest.raises(ClothInputError, match="--dts"):
        validate_stability_args("cotton", "1/60,0.0166667", "walk", "mg", 500, 1.0, 1)
    # Steps longer than a pose message go through 2..7 of them; the resolution is an axis.
    cfg = validate_stability_args("cotton", "1/15,1/10,7/30", "walk", "mg", "500,2400", 1.0,
                                  1)
    assert cfg.dts == [pytest.approx(2 / 30), pytest.approx(3 / 30), pytest.approx(7 / 30)]
    assert cfg.particles == [500, 2400]
    for bad in ("1/9", "8/30"):
        with pytest.raises(ClothInputError, match="spans"):
            validate_stability_args("cotton", bad, "walk", "mg", 500, 1.0, 1)
    with pytest.raises(ClothInputError, match="twice"):
        validate_stability_args("cotton", "1/30", "walk", "mg", "500,500", 1.0, 1)


def test_validation_of_the_scheme_axis():
    cfg = validate_stability_args("cotton", "1/30", "walk", "mg", 500, 1.0, 1)
    assert cfg.schemes == ["euler", "bdf2", "genalpha"]
    assert cfg.spectral_radius == DEFAULT_SPECTRAL_RADIUS
    cfg = validate_stability_args("cotton", "1/30", "walk", "mg", 500, 1.0, 1,
                                  schemes="GenAlpha, euler", spectral_radius="0.8")
    assert cfg.schemes == ["genalpha", "euler"] and cfg.spectral_radius == 0.8
    with pytest.raises(ClothInputError) as err:
        validate_stability_args("cotton", "1/30", "walk", "mg", 500, 1.0, 1,
                                schemes="bdf2,newmark,rk4", spectral_radius="1.5")
    msg = str(err.value)
    for part in ("newmark", "rk4", "--spectral-radius", "1.5", "euler, bdf2, genalpha"):
        assert part in msg, part
    for schemes, radius, words in (("bdf2,bdf2", None, "twice"), ("", None, "at least one"),
                                   ("euler,bdf2", "0.3", "does not list genalpha"),
                                   ("genalpha", "x", "'x'"), ("genalpha", "-0.1", "0..1")):
        with pytest.raises(ClothInputError, match=words):
            validate_stability_args("cotton", "1/30", "walk", "mg", 500, 1.0, 1,
                                    schemes=schemes, spectral_radius=radius)


def _one_cell_map(tmp_path, *options: str) -> dict:
    """The JSON of a map of one cotton cell (walk, 1/30 s, mg, 0.3 s) with ``options``."""
    out_json, out_png = tmp_path / "st.json", tmp_path / "st.png"
    assert main(["bench", "stability", "--materials", "cotton", "--dts", "1/30",
                 "--motions", "walk", "--solvers", "mg", "--seconds", "0.3", "--workers", "1",
                 *options, "--json", str(out_json), "--png", str(out_png)]) == 0
    return json.loads(out_json.read_text())


def test_the_linearisation_reaches_the_cells_it_concerns(tmp_path):
    with pytest.raises(ClothInputError, match="--linearise"):
        validate_stability_args("cotton", "1/30", "walk", "mg", 500, 1.0, 1, linearise="end")
    result = _one_cell_map(tmp_path, "--schemes", "bdf2,genalpha", "--linearise", "prediction")
    assert result["meta"]["linearise_at"] == "prediction"
    assert {(c["scheme"], c["linearise_at"], c["outcome"]) for c in result["cells"]} == {
        ("bdf2", "prediction", "ok"), ("genalpha", "start", "ok")}


def test_friction_inside_the_solve_reaches_every_cell(tmp_path):
    for value, words in (("after", "--contact-friction"), ("solve", "linearised at the start")):
        with pytest.raises(ClothInputError, match=words):
            validate_stability_args("cotton", "1/30", "walk", "mg", 500, 1.0, 1,
                                    linearise="prediction" if value == "solve" else "start",
                                    contact_friction=value)
    result = _one_cell_map(tmp_path, "--schemes", "bdf2", "--contact-friction", "solve")
    assert result["meta"]["contact_friction"] == "solve"
    assert [(c["contact_friction"], c["outcome"]) for c in result["cells"]] == [
        ("solve", "ok")]


def test_cli_rejects_bad_options(capsys):
    rc = main(["bench", "stability", "--materials", "tweed", "--particles", "5.5",
               "--dts", "1/45", "--schemes", "bdf2,leapfrog"])
    assert rc == 2
    err = capsys.readouterr().err
    assert "tweed" in err and "--particles" in err and "1/45" in err and "leapfrog" in err


# -- one tiny map -------------------------------------------------------------------------
def test_tiny_map_through_the_cli(tmp_path, capsys):
    out_json, out_png = tmp_path / "st.json", tmp_path / "st.png"
    rc = main(["bench", "stability", "--materials", "cotton", "--dts", "1/60,1/30,1/15",
               "--motions", "walk", "--solvers", "mg,explicit", "--seconds", "0.3",
               "--schemes", "euler,genalpha", "--spectral-radius", "0.8",
               "--workers", "1", "--json", str(out_json), "--png", str(out_png)])
    assert rc == 0
    result = json.loads(out_json.read_text())
    cells = result["cells"]
    assert len(cells) == 9  # per step: mg under each scheme, the explicit solver once
    for c in cells:
        assert {"material", "dt", "motion", "solver", "scheme", "outcome"} <= set(c)
        assert c["outcome"] in OUTCOMES and c["material"] == "cotton" and c["motion"] == "walk"
        assert c["levels"] >= 3 and c["wall_s"] > 0.0
    assert sorted({c["dt"] for c in cells}) == [pytest.approx(1 / 60), pytest.approx(1 / 30),
                                                 pytest.approx(2 / 30)]
    assert sorted((c["scheme"], c["solver"]) for c in cells) == sorted(
        3 * [("euler", "mg"), ("genalpha", "mg"), (EXPLICIT_SCHEME, "explicit")])
    assert {c["spectral_radius"] for c in cells if c["scheme"] == "genalpha"} == {0.8}
    assert {c["spectral_radius"] for c in cells if c["scheme"] != "genalpha"} == {None}
    mg = [c for c in cells if c["solver"] == "mg"]
    assert all(c["outcome"] == "ok" for c in mg)
    assert all(c["iterations_median"] >= 1 for c in mg)
    # The scheme reaches the simulation: from the same settled garment, implicit Euler and
    # generalised-alpha leave the dress on different paths.
    for dt in ("1/60", "1/30", "1/15"):
        euler, ga = (next(c for c in mg if c["dt_label"] == dt and c["scheme"] == s)
                     for s in ("euler", "genalpha"))
        assert euler["max_speed"] != ga["max_speed"]
    # 9 pose messages: 9 ticks of 2 or 1 steps, or 5 ticks of one step through 2 messages.
    by_dt = {c["dt_label"]: c for c in mg if c["scheme"] == "genalpha"}
    assert (by_dt["1/60"]["messages"], by_dt["1/60"]["steps"]) == (9, 18)
    assert (by_dt["1/30"]["messages"], by_dt["1/30"]["steps"]) == (9, 9)
    assert (by_dt["1/15"]["messages"], by_dt["1/15"]["steps"]) == (5, 5)
    assert by_dt["1/15"]["messages_per_step"] == 2
    (slow,) = [c for c in cells if c["solver"] == "explicit" and c["dt_label"] == "1/30"]
    assert slow["outcome"] != "ok" and slow["stopped_early"]
    summary = result["summary"]
    assert summary["mg_ok_everywhere"] is True
    assert summary["mg_ok_by_scheme"] == {"euler": True, "genalpha": True}
    assert summary["counts"]["mg"]["ok"] == 6
    assert summary["by_scheme"]["euler"]["mg"]["ok"] == 3
    assert summary["by_scheme"]["genalpha"]["mg"]["ok"] == 3
    assert sum(summary["by_scheme"][EXPLICIT_SCHEME]["explicit"].values()) == 3
    meta = result["meta"]
    assert meta["schemes"] == ["euler", "genalpha"] and meta["spectral_radius"] == 0.8
    assert meta["bounds"]["max_penetration_m"] == MAX_PENETRATION
    img = plt.imread(out_png)
    assert img.shape[0] > 100 and img.shape[1] > 100
    text = capsys.readouterr().out
    assert "mg (euler) ok in every cell: yes" in text and "genalpha mg" in text
    assert "euler mg" in text and "explicit" in text


def test_the_map_gives_the_same_cells_through_dask_as_in_process(dask_local):
    """The same units in this process and as tasks on two Dask workers: same outcomes, same
    messages and steps, and (one thread, the same inputs) the same worst figures."""
    from cloth_mg_ros.bench.stability import bench_stability

    cfg = validate_stability_args("cotton,leather", "1/30,1/15", "walk", "mg,mpcg", 500, 0.3, 1,
                                  schemes="genalpha")
    here = bench_stability(cfg, log=lambda line: None)["cells"]
    there = bench_stability(cfg, log=lambda line: None, client=dask_local)["cells"]
    assert len(here) == len(there) == 8
    keys = ("material", "dt", "motion", "solver", "scheme", "outcome", "messages", "steps",
            "iterations_median")
    assert [{k: c[k] for k in keys} for c in here] == [{k: c[k] for k in keys} for c in there]
    for a, b in zip(here, there, strict=True):
        assert a["max_speed"] == pytest.approx(b["max_speed"], rel=1e-6)
        assert a["max_penetration"] == pytest.approx(b["max_penetration"], abs=1e-9)


# -- what the map found in the core (regressions) -----------------------------------------
def test_pinched_particles_leave_two_overlapping_capsules():
    """Cloth between two capsules that overlap by 5 cm (a jumper's thighs): pushed out of one
    into the other and back, it used to stay up to 5 cm inside; now nothing is left inside."""
    from cloth_mg_ros.collision.capsules import CapsuleCollider
    from cloth_mg_ros.collision.colliders import penetration, resolve_contacts

    cap = CapsuleCollider(np.array([0.08, 0.08]), friction=0.5).at()
    p0 = np.array([[-0.053, 0.0, 0.1], [0.053, 0.0, 0.1]])
    cap.set_pose(p0, p0 + [0.0, 0.0, 0.8])
    cap.set_pose(p0, p0 + [0.0, 0.0, 0.8], 1.0 / 60.0)
    rng = np.random.default_rng(1)
    x = np.column_stack([rng.uniform(-0.02, 0.02, 200), rng.uniform(-0.05, 0.05, 200),
                         rng.uniform(0.3, 0.7, 200)])
    start = x.copy()
    v = np.zeros_like(x)
    count, deepest = resolve_contacts([cap], x, v, 0.006, x.copy())
    assert count == 200 and deepest > 0.03
    assert penetration([cap], x) == 0.0
    assert np.linalg.norm(x - start, axis=1).max() < 0.2  # out of the crease, not flung


def _drape_sim(material):
    from cloth_mg_ros.sim.simulator import Simulator
    from cloth_mg_ros.solvers import make_solver

    scene = build_scene("drape", 300, material)
    return Simulator(scene.model, scene.state, make_solver("direct"), dt=1.0 / 60.0)


def test_corrected_particles_are_not_driven_back_into_the_body():
    """A particle the contact projection corrected restarts its BDF2 history along the push
    (sim.friction; the incline's exact sliding checks the part along the surface), so the
    next step does not drive it back into the body: nothing is left inside after a step."""
    sim = _drape_sim(get_material("cotton"))
    sim.model = replace(sim.model, strain_limit=1.1)
    corrected = 0
    for _ in range(40):
        before = sim.state.x.copy()
        stats = sim.step()
        corrected += int(np.any(sim.state.x_prev != before, axis=1).sum())
        assert stats.max_penetration < 1e-9
    assert corrected > 100  # the sheet landed on the sphere


def test_strain_limit_moves_velocities_with_positions():
    """An implicit Euler step whose solve over-stretches the sheet: after the strain limit
    every free particle's velocity is the one that took it where it ended, x = x_n + h v."""
    from cloth_mg_ros.sim.integrator import assemble_step, finish_step

    scene = build_scene("hang", 200, get_material("cotton"))
    model = replace(scene.model, strain_limit=1.1)
    h = 1.0 / 60.0
    step = assemble_step(model, scene.state, h, "euler")
    dv = np.zeros((model.n, 3))
    dv[model.n // 2] = [0.0, 12.0, 0.0]  # 20 cm in one step: far past 1.1 x rest
    new, _, _ = finish_step(model, scene.state, step, dv, h)
    free = ~model.fixed_mask()
    np.testing.assert_allclose(new.x[free], scene.state.x[free] + h * new.v[free], atol=1e-12)
    assert np.linalg.norm(new.v[model.n // 2]) < 12.0  # the pull-back took speed off it
