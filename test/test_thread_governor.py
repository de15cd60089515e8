"""The steps' running threads under other work (budget.thread_governor): fewer threads while
other work holds the cores, all of them again once it is gone, the same cloth either way."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_mg_ros.budget.thread_governor import ThreadGovernor
from cloth_mg_ros.config import schema
from cloth_mg_ros.io.bags import bundled_bag, read_pose_frames
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.detail import DetailController
from cloth_mg_ros.sim.garment_sim import GarmentSim
from cloth_mg_ros.solvers.threads import available_threads


def _wait_share(cores: int, ours: int, others: int, noise: float = 0.0) -> float:
    """The run-queue wait share of `ours` busy threads among `others` on `cores` cores (each
    runnable thread gets cores / runnable of a core), plus an idle machine's 2 % and noise
    (the live node's own executor and DDS threads: 0.04-0.09 measured on an idle machine)."""
    runnable = ours + others
    return 0.02 + noise + (max(0.0, 1.0 - cores / runnable) if runnable > cores else 0.0)


def _run(g: ThreadGovernor, others_at, seconds: float, tick_s: float = 0.1,
         noise: tuple[float, float] = (0.0, 0.07)) -> list[tuple[float, int]]:
    """Feed g ticks of tick_s s for `seconds`, the other busy threads at time t being
    others_at(t), each tick's wait share with uniform noise in `noise`; returns (t, threads)
    after each tick."""
    out, t = [], 0.0
    rng = np.random.default_rng(7)
    while t < seconds:
        t += tick_s
        g.observe(t, _wait_share(g.cores, g.threads, others_at(t), rng.uniform(*noise)))
        out.append((round(t, 2), g.threads))
    return out


def test_two_threads_drop_to_one_under_a_load_and_come_back_after_it():
    g = ThreadGovernor(2, 2)
    trace = _run(g, lambda t: 2 if 6.0 <= t < 14.0 else 0, 24.0)
    assert all(n == 2 for t, n in trace if t < 6.0)
    down = next(t for t, n in trace if n == 1)
    assert 6.0 <= down <= 7.2  # within a window of the load's start
    assert all(n == 1 for t, n in trace if down <= t < 14.0)  # no tries while it lasts
    up = next(t for t, n in trace if t >= 14.0 and n == 2)
    assert up - 14.0 <= 2.5  # a quiet spell after the load
    assert all(n == 2 for t, n in trace if t >= up)
    assert g.changes == 2


def test_a_node_that_waits_more_when_idle_learns_its_own_baseline():
    """At a 10 Hz stream the node's own threads wait 8-22 % a tick on an idle machine (its
    ticks are short): the governor takes that as its baseline, and still drops under a load
    and comes back after it."""
    g = ThreadGovernor(2, 2)
    trace = _run(g, lambda t: 2 if 6.0 <= t < 14.0 else 0, 24.0, noise=(0.06, 0.2))
    assert all(n == 2 for t, n in trace if t < 6.0)
    assert 0.08 <= g.baseline <= 0.15
    assert any(n == 1 for t, n in trace if 6.0 <= t < 7.2)
    up = next(t for t, n in trace if t >= 14.0 and n == 2)
    assert up - 14.0 <= 2.5 and trace[-1][1] == 2


def test_one_other_busy_thread_is_tried_again_every_few_seconds():
    """Beside one busy process a 2-core machine has no room for two threads, which the wait
    share shows only while both run: each try costs two ticks, 2 s and then 4 s apart."""
    g = ThreadGovernor(2, 2)
    trace = _run(g, lambda t: 1, 60.0)
    tries = [t for (_, a), (t, b) in zip(trace, trace[1:], strict=False) if b > a]
    assert 10 <= len(tries) <= 15
    assert all(b - a >= 3.9 for a, b in zip(tries[1:], tries[2:], strict=False))
    on_two = sum(1 for _, n in trace if n == 2) / len(trace)
    assert on_two < 0.1
    assert trace[-1][1] == 1
    # the load ends: all threads again within the longest wait and a quiet spell
    g2 = ThreadGovernor(2, 2)
    trace = _run(g2, lambda t: 1 if t < 30.0 else 0, 40.0)
    assert next(t for t, n in trace if t >= 30.0 and n == 2) - 30.0 <= 6.5
    assert trace[-1][1] == 2


def test_many_cores_keep_the_threads_the_other_work_leaves():
    """Four other busy threads on 8 cores: about four threads of eight (the estimate is as
    rough as the wait share's noise), all eight tried again less and less often."""
    g = ThreadGovernor(8, 8)
    trace = _run(g, lambda t: 4 if t >= 3.0 else 0, 120.0)
    assert all(n == 8 for t, n in trace if t < 3.0)
    loaded = [n for t, n in trace if t >= 4.0]
    assert sum(1 for n in loaded if 3 <= n <= 5) / len(loaded) > 0.85


def test_without_a_wait_share_nothing_changes():
    g = ThreadGovernor(2, 2)
    assert all(g.observe(0.1 * k, None) is None for k in range(1, 200))
    assert g.threads == 2 and g.changes == 0
    with pytest.raises(ValueError, match="threads and cores"):
        ThreadGovernor(0, 2)


def test_a_starved_tick_longer_than_the_window_judges_alone():
    g = ThreadGovernor(2, 2)
    assert g.observe(0.1, 0.02) is None
    change = g.observe(2.5, 0.52)  # one 2.4 s tick beside two hogs
    assert change is not None and change.threads == 1
    assert "other busy threads" in change.reason


def test_the_level_of_detail_does_not_step_up_on_fewer_threads_than_it_timed():
    """Ticks on fewer threads than the rungs were timed on neither time a rung nor step up:
    once every thread runs again, the controller steps up as before."""
    c = DetailController([0, 1], rung_step_ms=(15.0, 3.0))
    t = 0.0
    for _ in range(90):  # the finest on an idle machine
        t += 1 / 30
        assert c.observe(t, 15.0, 2.0, 23.3, 33.3, [15.0, 3.0], 15.0, 1, 0.02) is None
    for _ in range(60):  # overruns at the finest: down
        t += 1 / 30
        c.observe(t, 40.0, 2.0, 23.3, 33.3, [15.0, 3.0], 40.0, 1, 0.5)
    assert c.index == 1
    for _ in range(300):  # idle, but on one thread of two: stays down
        t += 1 / 30
        assert c.observe(t, 4.0, 2.0, 23.3, 33.3, [15.0, 3.0], 4.0, 1, 0.02,
                         full_threads=False) is None
    up = None
    for _ in range(300):
        t += 1 / 30
        if c.observe(t, 3.0, 2.0, 23.3, 33.3, [15.0, 3.0], 3.0, 1, 0.02):
            up = t
            break
    assert up is not None and c.index == 0


@pytest.mark.skipif(available_threads() < 2, reason="one core: no threads to leave out")
def test_fewer_running_threads_give_the_same_cloth_bit_for_bit():
    """The sweeps split into the configured threads' parts whatever runs them."""
    walk = read_pose_frames(bundled_bag("walk"))

    def run(run_threads):
        options = schema.body_options(garment="dress", particles=600, threads=2,
                                 max_substep_motion=0.25, self_contact=True)
        g = GarmentSim.dress(Avatar.load(), walk[0][0], walk[0][1], get_material("cotton"),
                             options)
        g.run_threads = run_threads
        for k in range(1, 6):
            g.push(*walk[k])
        return g.positions.copy()

    assert np.array_equal(run(None), run(1))


def test_a_try_on_a_loaded_machine_drops_back_after_its_first_tick():
    """A try's first tick is a probe (the node keeps it from the level of detail): a loaded
    machine sends the count back down after it, not after a window of slow ticks."""
    g = ThreadGovernor(2, 2)
    g.observe(0.1, 0.02)
    assert g.observe(1.5, 0.52).threads == 1  # one long tick beside two busy processes
    t, tries = 1.5, 0
    while not g.probing:
        t += 0.3
        g.observe(t, 0.05)
        tries += 1
        assert tries < 20
    assert g.threads == 2 and t - 1.5 >= 2.0  # a quiet spell first
    change = g.observe(t + 0.3, 0.4)
    assert change is not None and change.threads == 1 and not g.probing


def test_a_step_that_waits_long_drops_the_threads_before_the_tick_ends():
    """Between a tick's steps only a clear overload counts (twice the busy margin over the
    baseline): a loaded machine's first tick on two threads ran 1.5-4.5 s."""
    g = ThreadGovernor(2, 2)
    assert g.observe_step(0.5, 0.25) is None  # noise, or a mild load: the tick judges
    assert g.observe_step(0.6, None) is None
    change = g.observe_step(1.0, 0.52)
    assert change is not None and change.threads == 1 and "a step's threads" in change.reason
    assert g.observe_step(1.5, 0.6) is None  # already on one thread


def test_a_tick_runs_its_next_steps_on_the_threads_between_steps_returns(monkeypatch):
    import cloth_mg_ros.sim.garment_sim as garment_sim_module
    walk = read_pose_frames(bundled_bag("walk"))
    options = schema.body_options(garment="dress", particles=600, threads=2, substeps=3)
    g = GarmentSim.dress(Avatar.load(), walk[0][0], walk[0][1], get_material("cotton"),
                         options)
    asked: list[int] = []
    monkeypatch.setattr(garment_sim_module, "use_threads", lambda n: asked.append(n) or n)
    calls: list[int] = []

    def between() -> int | None:
        calls.append(1)
        return 1

    g.between_steps = between
    g.push(*walk[1])
    assert len(calls) == 2  # between the three steps, not after the last
    assert g.run_threads == 1 and asked[-1] == 1
