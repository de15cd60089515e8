"""Levels of detail of a garment: its multigrid hierarchy as a ladder of resolutions, whose
steps are called rungs (rung k: the garment simulated on its hierarchy's level k; "level" alone
means a multigrid level).

Every garment is a coarse mesh subdivided 1-to-4, and subdivision keeps the coarse vertices
first with their indices (mesh.hierarchy), so level k's vertices are the first n_k of level
k-1's: the ladder's rungs share their material points. A rung is a whole simulation of the
garment at that level (model, solver, integrator) sharing the body's colliders and the pins
(coarse vertices, valid on every level) with the others.

Stepping down keeps the coarse vertices' positions and velocities as they are (a slice, bit
for bit), and the BDF2 history with them. Stepping up prolongates the coarse state with the
hierarchy's own operator (coarse vertices keep their values exactly, new ones are midpoints
of the coarse edges); a midpoint of two vertices outside a capsule can lie inside it (the
facet's sag), so the new vertices only are projected out of the colliders.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from cloth_mg_ros.collision.colliders import resolve_contacts
from cloth_mg_ros.collision.self_contact import SelfContact
from cloth_mg_ros.mesh.hierarchy import MeshHierarchy
from cloth_mg_ros.physics.materials import Material
from cloth_mg_ros.sim.model import ClothState, build_model
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.solvers import make_solver

MIN_RUNG_PARTICLES = 300  # a coarser rung draws too few particles for a garment to read as one
# Wait shares (budget.contention) this close count as the same contention: a rung's steps
# measured at one stand for it at the other. A step's time does not scale as 1 / (1 - wait
# share): the solver's threads meet at barriers, and with two threads on two cores beside two
# hogs (wait share 0.52) a 2394-particle tick took 429 ms where 24 ms x 1 / 0.48 was
# predicted; so a rung's steps are only compared at the contention they were measured at.
SAME_CONTENTION = 0.1


def sub_hierarchy(hierarchy: MeshHierarchy, level: int) -> MeshHierarchy:
    """The hierarchy below and including ``level`` (levels[level] becomes the finest)."""
    return MeshHierarchy(levels=list(hierarchy.levels[level:]),
                         transfers=list(hierarchy.transfers[level:]))


def rung_indices(hierarchy: MeshHierarchy, min_particles: int = MIN_RUNG_PARTICLES) -> list[int]:
    """The rungs a garment may be simulated at: its hierarchy's level 0 and every coarser
    level with at least ``min_particles`` vertices that keeps a coarser level under it (for
    the multigrid)."""
    out = [0]
    for k in range(1, len(hierarchy.levels) - 1):
        if hierarchy.levels[k].n_vertices >= min_particles:
            out.append(k)
    return out


def build_rung(hierarchy: MeshHierarchy, rung: int, material: Material, pins: np.ndarray,
               colliders: list, options, weft: np.ndarray, dt: float = 1.0 / 30.0,
               ) -> Simulator:
    """A simulation of the garment at ``rung`` (0: finest), at rest in its rest shape.

    pins: (k,) pinned vertex indices (coarse vertices); colliders: shared with the other
    rungs; options: a BodySimOptions (solver, tolerance, levels, threads, thickness,
    strain_limit, self_contact, scheme)."""
    hier = sub_hierarchy(hierarchy, rung)
    mesh = hier.levels[0]
    model = build_model(mesh, material, pinned=pins, colliders=colliders, weft=weft,
                        thickness=options.thickness,
                        compression=options.compression,
                        contact_friction=options.contact_friction)
    model = replace(model, strain_limit=options.strain_limit, self_contact=(
        SelfContact.for_mesh(mesh.rest, mesh.edges) if options.self_contact else None))
    solver = rung_solver(hierarchy, rung, model.bending, options)
    state = ClothState.at_rest(np.array(mesh.rest))
    return Simulator(model, state, solver, dt=dt, scheme=options.scheme, track_energy=False,
                     spectral_radius=options.spectral_radius,
                     newton_iterations=options.newton_iterations,
                     linearise_at=options.linearise_at)


def rung_solver(hierarchy: MeshHierarchy, rung: int, bending, options):
    """The linear solver of ``rung``: options' solver, tolerance (its solve_tolerance at the
    rung's size), multigrid levels and threads on the hierarchy below it."""
    tol = options.solve_tolerance(hierarchy.levels[rung].n_vertices, rung)
    return make_solver(options.solver, tol=tol,
                       hierarchy=sub_hierarchy(hierarchy, rung), bending=bending,
                       levels=options.levels, threads=options.threads)


def restrict_state(state: ClothState, n_coarse: int) -> ClothState:
    """The state of the coarse vertices (the first ``n_coarse``), history included: copies
    of the same numbers."""
    def cut(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else np.array(a[:n_coarse])

    return ClothState(cut(state.x), cut(state.v), cut(state.x_prev), cut(state.v_prev),
                      state.t, cut(state.a), dict(state.bodies), cut(state.contact_force))


def prolongate_state(hierarchy: MeshHierarchy, state: ClothState, coarse: int, fine: int,
                     colliders: list, thickness: float) -> ClothState:
    """The state at level ``coarse`` carried up to level ``fine`` (< coarse) with the
    hierarchy's prolongations; new vertices found inside a collider are projected out
    (positions only: their velocities keep the interpolated values). colliders: the rungs'
    (shared) colliders at the state's poses (ClothState.colliders)."""
    x, v, xp, vp, a = state.x, state.v, state.x_prev, state.v_prev, state.a
    for k in range(coarse - 1, fine - 1, -1):
        p = hierarchy.transfers[k].prolongation()
        x, v = p @ x, p @ v
        xp = None if xp is None else p @ xp
        vp = None if vp is None else p @ vp
        a = None if a is None else p @ a
    n_old = len(state.x)
    new_x = np.ascontiguousarray(x[n_old:])
    before = new_x.copy()
    scratch_v = np.zeros_like(new_x)
    resolve_contacts(colliders, new_x, scratch_v, thickness)
    if xp is not None:  # BDF2's history moves with the projection: no push in its next step
        xp = np.array(xp)
        xp[n_old:] += new_x - before
    x = np.concatenate([np.asarray(state.x), new_x])  # coarse vertices: exactly as they were
    v = np.concatenate([np.asarray(state.v), v[n_old:]])
    if a is not None:  # the coarse vertices' own, exactly as they were
        a = np.concatenate([np.asarray(state.a), a[n_old:]])
    force = state.contact_force  # the new vertices' contacts are not known yet
    if force is not None:
        force = np.concatenate([force, np.zeros(len(x) - n_old)])
    return ClothState(x, v, xp, vp, state.t, a, dict(state.bodies), force)


@dataclass
class RungSwitch:
    """A decision of the DetailController: go to ``rung`` (0 finest) because ``reason``."""

    rung: int
    reason: str


@dataclass
class DetailController:
    """Live level of detail: watches tick times against the budget and picks the rung.

    rungs: the garment's allowed rungs (`rung_indices`), finest first. Each tick the caller
    passes the cost model's predicted tick (ms) at every rung for the stream's period now,
    and how many steps the tick took.

    What a rung costs. With the machine's contention (each tick's `wait_share`: the share of
    its threads' time the process spent waiting for a core, budget.contention), each rung's
    own steps as it ran (the median ms per step over an `up_window_s` at it) and the median
    wait share they were measured at, kept from the least contended window (a window within
    half SAME_CONTENTION of it replaces it, following the motion); a rung not run yet is scaled
    from the nearest one that was by rung_step_ms, each rung's ms per step timed on the
    garment when it was dressed (GarmentSim.time_rungs), else the cost model's tick. (Timed
    at rest, a coarse rung at its tighter tolerance stepped relatively slower in motion than
    the finest, by more than the `agree` guard, so a recovered machine looked loaded there
    and the garment stayed down.) Without contention figures: rung_step_ms
    anchored live by the lowest median ms per step over an `up_window_s` at the finest rung
    (until one is measured, the cost model's tick there), or the cost model's predictions
    alone. A rung's tick is its ms per step times the steps the ticks take now.

    Down: when the ticks of the last `down_window_s` cost more than the budget on average (or
    the lag grows past `max_lag_periods` pose periods), to the finest coarser rung whose
    tick, slowed as much as the steps here are against this rung's own prediction, fits
    `up_margin` of the budget (the coarsest if none does): one switch for a load, not one
    rung a second.
    Up: to the finest rung whose predicted tick (its steps, plus the publishing measured
    here) fits `up_margin` of the budget, when the wait share over the last `up_window_s`
    is within SAME_CONTENTION of the one its steps were measured at (a machine that is still
    loaded waits more, and stays down). Without contention figures, only when
    the steps measured here agree with this rung's own prediction (their median at most
    `agree` times it: a machine that is still loaded steps slower, and stays down).
    Hysteresis: after any switch, `down_window_s` before the next step down and `up_window_s`
    before a step up; a step up that has to be undone within `failed_up_s` (the prediction
    was wrong for this machine) multiplies the wait before the next step up by `backoff`,
    and a step up that holds resets it: no flapping."""

    rungs: list[int]
    rung_step_ms: Sequence[float] | None = None
    down_window_s: float = 1.0
    up_window_s: float = 2.0
    up_margin: float = 0.8
    agree: float = 1.5
    max_lag_periods: float = 6.0
    failed_up_s: float = 5.0
    backoff: float = 3.0
    index: int = 0
    switches: int = 0
    _ticks: deque = field(default_factory=deque)
    _since: float | None = None
    _up_wait_s: float | None = None  # the wait before the next step up, s
    _last_up: float | None = None  # when the last step up was made, s
    _anchor_ms: float | None = None  # ms per step at the finest rung, measured live
    _own: dict = field(default_factory=dict)  # rung index: (its ms per step, wait share)

    def __post_init__(self) -> None:
        if self.rung_step_ms is not None and len(self.rung_step_ms) != len(self.rungs):
            raise ValueError(f"rung_step_ms has {len(self.rung_step_ms)} values for "
                             f"{len(self.rungs)} rungs")

    @property
    def rung(self) -> int:
        return self.rungs[self.index]

    def rung_ticks(self, predicted_ms: Sequence[float], steps: float) -> list[float]:
        """Each rung's tick (its steps only), ms, for ticks of ``steps`` steps: from the
        rungs' own timings anchored live (see the class), or the cost model's
        ``predicted_ms``."""
        own, live = self.rung_step_ms, self._own
        if live:
            out = []
            for i, p in enumerate(predicted_ms):
                if i in live:
                    out.append(live[i][0] * steps)
                elif own is not None:
                    k = self._nearest(i)
                    out.append(live[k][0] * steps * float(own[i]) / float(own[k]))
                else:
                    out.append(float(p))
            return out
        if own is None:
            return [float(p) for p in predicted_ms]
        finest = self._anchor_ms * steps if self._anchor_ms is not None else predicted_ms[0]
        return [float(finest) * float(t) / float(own[0]) for t in own]

    def _nearest(self, i: int) -> int:
        """The rung index nearest `i` whose own steps were measured (some were)."""
        return min(self._own, key=lambda j: abs(j - i))

    def _basis(self, i: int) -> float:
        """The wait share rung index `i`'s prediction was measured at (its own, or that of
        the nearest measured rung it is scaled from)."""
        return self._own[i][1] if i in self._own else self._own[self._nearest(i)][1]

    def observe(self, now_s: float, tick_ms: float, lag_ms: float, budget_ms: float,
                period_ms: float, predicted_ms: Sequence[float],
                step_ms: float | None = None, steps: int | None = None,
                wait_share: float | None = None, full_threads: bool = True
                ) -> RungSwitch | None:
        """Record one tick (wall clock now_s, its cost tick_ms, the lag behind the newest
        pose lag_ms) and return the switch to make, if any. predicted_ms[i]: the cost
        model's tick at rungs[i] (ms) for the pose period now; step_ms: the part of tick_ms
        the simulation's steps took (None: all of it); steps: how many steps (None: 1). The
        rest (publishing) is measured here and added to the finer rung's prediction.
        wait_share: the share of the process's threads' time spent waiting for a core since
        the last tick (0..1; None: unknown, budget.contention); full_threads: False while the
        steps run on fewer threads than the rungs were timed on (budget.thread_governor):
        such ticks neither stand for a rung's own steps nor step up."""
        if self._since is None:
            self._since = now_s
        if self._up_wait_s is None:
            self._up_wait_s = self.up_window_s
        if self._last_up is not None and now_s - self._last_up > self.failed_up_s:
            self._up_wait_s, self._last_up = self.up_window_s, None  # the step up held
        self._ticks.append((now_s, tick_ms, lag_ms, tick_ms if step_ms is None else step_ms,
                            max(int(steps or 1), 1),
                            None if wait_share is None else min(max(wait_share, 0.0), 1.0),
                            full_threads))
        horizon = max(self.down_window_s, self.up_window_s)
        while self._ticks and self._ticks[0][0] < now_s - horizon:
            self._ticks.popleft()
        held = now_s - self._since
        # the ticks that may time this rung and step up: on every thread the rungs were timed on
        window = [t for t in self._ticks if t[0] >= now_s - self.up_window_s and t[6]]
        contention = self._measure(window, held)
        recent = [t for t in self._ticks if t[0] >= now_s - self.down_window_s]
        if len(recent) < 3 <= len(self._ticks):
            # ticks slower than a third of the window (a heavy load): the last three, all
            # made since the last switch (_switch clears the ticks), judge the rung
            recent = list(self._ticks)[-3:]
        ticks = self.rung_ticks(predicted_ms, float(np.median([t[4] for t in recent or window])))
        if held >= self.down_window_s and self.index < len(self.rungs) - 1 and\
                len(recent) >= 3:
            down = self._down(now_s, recent, ticks, budget_ms, period_ms)
            if down is not None:
                return down
        if held >= self._up_wait_s and self.index > 0 and len(window) >= 3 and full_threads:
            return self._up(now_s, window, ticks, budget_ms, contention)
        return None

    def _measure(self, window: list, held: float) -> float | None:
        """What the ticks of the last `up_window_s` say of this rung: its own ms per step on
        an idle machine (with wait shares), the finest's live anchor (without); returns
        their median wait share (None: unknown)."""
        waits = [t[5] for t in window]
        contention = float(np.median(waits)) if waits and None not in waits else None
        if contention is not None and len(window) >= 3:
            kept = self._own.get(self.index)
            if kept is None or contention <= kept[1] + SAME_CONTENTION / 2:
                self._own[self.index] = (float(np.median([t[3] / t[4] for t in window])),
                                         contention)
        if self.index == 0 and len(window) >= 3 and held >= self.up_window_s:
            per_step = float(np.median([t[3] / t[4] for t in window]))
            if self._anchor_ms is None or per_step < self._anchor_ms:
                self._anchor_ms = per_step
        return contention

    def _down(self, now_s: float, recent: list, ticks: list[float], budget_ms: float,
              period_ms: float) -> RungSwitch | None:
        """The step down the `recent` ticks ask for (class docstring), if any."""
        mean = sum(t[1] for t in recent) / len(recent)
        lag = recent[-1][2]
        if mean <= budget_ms and lag <= self.max_lag_periods * period_ms:
            return None
        why = (f"ticks took {mean:.0f} ms on average over {self.down_window_s:g} s "
               f"(budget {budget_ms:.0f} ms)" if mean > budget_ms else
               f"lag {lag:.0f} ms behind the newest pose")
        if self._last_up is not None:  # the last step up did not hold
            self._up_wait_s *= self.backoff
            self._last_up = None
        steps_here = float(np.median([t[3] for t in recent]))
        slow = max(steps_here / ticks[self.index], 1.0) if ticks[self.index] > 0 else 1.0
        rest = max(mean - sum(t[3] for t in recent) / len(recent), 0.0)
        to = next((j for j in range(self.index + 1, len(self.rungs))
                   if ticks[j] * slow + rest <= self.up_margin * budget_ms),
                  len(self.rungs) - 1)
        return self._switch(now_s, to, why + f"; steps {slow:.1f}x this rung's own")

    def _up(self, now_s: float, window: list, ticks: list[float], budget_ms: float,
            contention: float | None) -> RungSwitch | None:
        """The step up the `window`'s ticks allow (class docstring), if any."""
        steps = float(np.median([t[3] for t in window]))
        rest = max(float(np.median([t[1] for t in window])) - steps, 0.0)
        here = ticks[self.index]
        fits = [j for j in range(self.index) if ticks[j] + rest <= self.up_margin * budget_ms
                and (contention is None or contention <= self._basis(j) + SAME_CONTENTION)]
        if not fits or (contention is None and steps > self.agree * here):
            return None
        self._last_up = now_s
        to = fits[0]
        why = (f"steps of {steps:.1f} ms a tick (median over {self.up_window_s:g} s) "
               f"agree with this rung's {here:.1f} ms" if contention is None else
               f"the node's threads waited {100 * contention:.0f} % of their time for "
               f"a core (median over {self.up_window_s:g} s), rung {self.rungs[fits[0]]}'s "
               f"steps were measured at {100 * self._basis(fits[0]):.0f} %")
        return self._switch(
            now_s, to,
            f"{why}; rung {self.rungs[to]}'s steps predict {ticks[to] + rest:.1f} ms "
            f"for a tick there, publishing included (budget {budget_ms:.0f} ms)")

    def _switch(self, now_s: float, index: int, reason: str) -> RungSwitch:
        self.index = index
        self.switches += 1
        self._since = now_s
        self._ticks.clear()
        return RungSwitch(self.rungs[index], reason)
