"""Memory traffic of the multigrid solve: bytes moved per V-cycle, per CG iteration and per
tick, against the machine's measured memory bandwidth (issue 25).

Units: bytes (B) in the counts, MB = 1e6 B and GB/s = 1e9 B/s in the reports, times in ms.

The counts follow the kernels of one MG-preconditioned CG iteration on packed levels
(solvers.packed_kernels) and take every size and item size from the PackedLevels' own
arrays (solvers.packed_levels): per row, level l's rows ``voff[l]:voff[l+1]``, the slot
starts / mids / stops (int32), ``dinv6`` / ``diag6`` (total, 6) float64, ``free`` (total,)
float64, ``parents`` (total, 2) int32 and the vectors ``b``, ``x``, ``r`` (total, 3) float64;
per slot, its neighbour (int32) and its block: 6 float64 in a full slot (``frows``), one in
a scalar slot (``swts``). How many slots a row reads comes from the arrays too: ``stop -
start`` all of them (a backward sweep, a product), ``mid - start`` the earlier neighbours'
(the first sweep from zero) and ``stop - mid`` the later ones' (the residual it leaves).
The finest level's backward sweep also forms the outer CG's product (w = S A z), so an
iteration has no separate pass over the finest blocks; the solve's first residual gathers
only on the rows its pins reach (`first_guess_bytes`).

What is an estimate here, and which way it errs:

* each array a kernel streams is counted once per pass, read or written, as if nothing
  stayed in the caches between kernels (the coarse levels, a few hundred KB, usually do:
  their bytes are an upper bound);
* a slot's neighbour vector (x_j or p_j, 24 B) is counted once per slot. Neighbours are
  mostly rows close by, already in the cache, so this term is an upper bound too (the real
  traffic lies between the count without it and the count with it);
* scattered updates within a row's neighbourhood (the last sweep's w_j += A_ji z_i, the
  prolongation's parent rows) hit rows just touched and are not counted again, nor is a
  write's line fill (write-allocate), as STREAM does not count it;
* pinned rows, which the sweeps skip, are counted like free ones (a few hundred rows);
* the coarsest level's Cholesky factor (CHOLMOD's, of its 100-350 rows) is not counted,
  only the b it reads and the x it writes.

Achieved bandwidth = counted bytes / measured time; compared with a STREAM-like triad
(`stream_bandwidth`), it says how close to the memory's limit a part runs. The triad
streams arrays far larger than the caches; where an iteration's whole working set
(`working_set_bytes`) fits in the last-level cache, as 20K particles' ~18 MB do in a 32 MB
L3, the levels are not fetched from memory every iteration and a part can pass the triad.

Per solve and per tick (`tick_bytes_estimate`) only the bytes are counted, not their time:
the run measures a solve's and a tick's wall time only, which hold work whose bytes are not
counted (the coarsening, the coarsest factorisation, the assembly, collisions). Their rows
divide the counted bytes by that wall time: an average rate over the solve or tick, a lower
bound on the rate the counted kernels reach, and not set against the triad.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from numba import njit, prange

from cloth_mg_ros.io.text_table import text_table
from cloth_mg_ros.sim.integrator import assemble_step
from cloth_mg_ros.solvers.multigrid import CoarseSolver
from cloth_mg_ros.solvers.packed_kernels import (
    cg_update,
    direction_update,
    vcycle_down,
    vcycle_up,
)
from cloth_mg_ros.solvers.packed_levels import PackedLevels
from cloth_mg_ros.solvers.threads import threads_for_block, use_threads

__all__ = ["first_guess_bytes", "format_traffic", "iteration_bytes", "last_level_cache_bytes",
           "measure_traffic", "packing_bytes", "stream_bandwidth", "tick_bytes_estimate",
           "time_iteration", "working_set_bytes"]

MB = 1e6
GB = 1e9


# -- the machine's bandwidth ------------------------------------------------------------------
@njit(cache=True, nogil=True, parallel=True)
def _fill(a, value):
    # written by the threads that later stream it: each page lands near its thread (first
    # touch), as in STREAM's own initialisation
    for i in prange(a.shape[0]):
        a[i] = value


@njit(cache=True, nogil=True, parallel=True)
def _triad(a, b, c, s):
    for i in prange(a.shape[0]):
        a[i] = b[i] + s * c[i]


@njit(cache=True, nogil=True, parallel=True)
def _copy(a, b):
    for i in prange(a.shape[0]):
        a[i] = b[i]


def stream_bandwidth(threads: int, mb: int = 256, repeats: int = 5) -> dict:
    """The memory bandwidth a STREAM-like triad a = b + s c and copy a = b reach on
    ``threads`` numba threads (0: every core), over three float64 arrays of ``mb`` MB (2^20 B)
    in all, far larger than the caches at the default 256 MB; the best of ``repeats`` runs.
    Bytes are counted as STREAM counts them: 3 x 8 B per element for the triad, 2 x 8 for
    the copy (the write's line fill not counted). Returns {"triad_gbs", "copy_gbs",
    "threads"} in GB/s (1e9 B/s). The calling thread's numba thread count is restored."""
    with threads_for_block(threads) as count:
        n = max(1, int(mb) * 2**20 // (3 * 8))
        a, b, c = (np.empty(n) for _ in range(3))
        for arr, value in ((a, 0.0), (b, 1.0), (c, 2.0)):
            _fill(arr, value)
        _triad(a, b, c, 3.0)  # compile (or load from the cache) before timing
        _copy(a, b)
        best_triad = best_copy = float("inf")
        for _ in range(max(1, int(repeats))):
            t0 = time.perf_counter()
            _triad(a, b, c, 3.0)
            t1 = time.perf_counter()
            _copy(a, b)
            t2 = time.perf_counter()
            best_triad = min(best_triad, t1 - t0)
            best_copy = min(best_copy, t2 - t1)
        item = a.itemsize
        return {"triad_gbs": 3 * item * n / best_triad / GB,
                "copy_gbs": 2 * item * n / best_copy / GB, "threads": count}


# -- bytes of one iteration ---------------------------------------------------------------------
def _row_bytes(a: np.ndarray) -> int:
    """Bytes of one row of a (n, ...) array (its item size for a 1-d one)."""
    return a.itemsize * int(np.prod(a.shape[1:], dtype=np.int64))


def _slot_counts(start: np.ndarray, mid: np.ndarray, stop: np.ndarray, lo: int,
                 hi: int) -> tuple[int, int]:
    """(all slots, earlier neighbours' slots) of rows lo..hi."""
    every = int(np.sum(stop[lo:hi].astype(np.int64) - start[lo:hi]))
    earlier = int(np.sum(mid[lo:hi].astype(np.int64) - start[lo:hi]))
    return every, earlier


def _sweep_terms(pk: PackedLevels, lvl: int) -> dict:
    """Level lvl's slot counts and per-slot / per-row byte sizes, from the arrays."""
    fstart, fmid, fstop, fnbr, frows, sstart, smid, sstop, snbr, swts = pk.slots
    lo, hi = int(pk.voff[lvl]), int(pk.voff[lvl + 1])
    full, full_early = _slot_counts(fstart, fmid, fstop, lo, hi)
    scal, scal_early = _slot_counts(sstart, smid, sstop, lo, hi)
    full_slot = fnbr.itemsize + _row_bytes(frows)  # neighbour + upper triangle of a block
    scal_slot = snbr.itemsize + _row_bytes(swts)  # neighbour + one weight
    return {"rows": hi - lo, "full": full, "full_early": full_early, "scalar": scal,
            "scalar_early": scal_early, "full_slot": full_slot, "scalar_slot": scal_slot,
            # a row's first and last slot of each set (a backward sweep, a product), its
            # first and middle one (the first sweep), or its middle and last (its residual)
            "ends": fstart.itemsize + fstop.itemsize + sstart.itemsize + sstop.itemsize,
            "firsts": fstart.itemsize + fmid.itemsize + sstart.itemsize + smid.itemsize,
            "lasts": fmid.itemsize + fstop.itemsize + smid.itemsize + sstop.itemsize}


def iteration_bytes(pk: PackedLevels) -> dict:
    """Bytes one MG-preconditioned CG iteration moves on the packed levels ``pk`` (module
    docstring: what is counted and which terms are upper bounds).

    Returns {"levels": [...], "coarse", "take", "product", "outer", "vcycle", "iteration"}
    in bytes. "levels": one dict per swept level (every level but the coarsest; the one
    level of a one-level hierarchy) with "level", "rows", "slots", "earlier_slots", "down"
    and "up" (totals) and "terms", the parts they add up from: down = load (level 0: r0 into
    b) + down_rows + down_slots + down_gather + restrict (the first sweep reads the earlier
    neighbours' slots, its residual the later ones': every slot once); up = prolong +
    up_rows + up_slots + up_gather + up_product (level 0: the product w = S A z its sweep
    forms, diag6 read and w written). "coarse": the coarsest level's b read and x written;
    "take": z = S x and z . r0; "product": q = S A p as a pass of its own (the solve's first
    residual); "outer": p = z + beta p, q = w + beta q, and cg_update's x, r; vcycle = sum of
    down + coarse + sum of up + take; iteration = vcycle + outer. "gathers": the
    neighbour-vector terms inside those totals, {"down", "up", "product", "iteration"}: the
    totals less these are the counts without them, a lower bound where the neighbours come
    from the cache.
    """
    levels = pk.n_levels
    vec = _row_bytes(pk.x)  # one row of b, x, r, z, p, q: 3 float64
    free = _row_bytes(pk.free)
    dinv = _row_bytes(pk.dinv6)
    parents = _row_bytes(pk.parents)
    out = [_level_bytes(pk, lvl, vec, free, dinv, parents)
           for lvl in range(max(levels - 1, 1))]
    coarse = 0
    if levels > 1:
        coarse = 2 * vec * int(pk.voff[-1] - pk.voff[-2])  # b read, x written
    fine = _sweep_terms(pk, 0)
    n0 = fine["rows"]
    take = n0 * (free + 3 * vec)  # free, x, r0 read; z written
    product_gather = (fine["full"] + fine["scalar"]) * vec  # the neighbours' p
    product = (n0 * (fine["ends"] + _row_bytes(pk.diag6) + free + 2 * vec)  # p_i read, q written
               + fine["full"] * fine["full_slot"] + fine["scalar"] * fine["scalar_slot"]
               + product_gather)
    direction = 6 * vec * n0  # z, w, p, q read; p, q written
    update = 6 * vec * n0  # x, r read and written; p, q read
    outer = direction + update
    vcycle = sum(lv["down"] + lv["up"] for lv in out) + coarse + take
    gathers = {"down": sum(lv["terms"]["down_gather"] for lv in out),
               "up": sum(lv["terms"]["up_gather"] for lv in out), "product": product_gather}
    gathers["iteration"] = gathers["down"] + gathers["up"]
    return {"levels": out, "coarse": coarse, "take": take, "product": product,
            "outer": outer, "vcycle": vcycle, "iteration": vcycle + outer, "gathers": gathers}


def _level_bytes(pk: PackedLevels, lvl: int, vec: int, free: int, dinv: int,
                 parents: int) -> dict:
    """`iteration_bytes`' figures of swept level ``lvl``; vec, free, dinv, parents: the bytes
    of a row of the vectors, free, dinv6 and parents."""
    levels = pk.n_levels
    t = _sweep_terms(pk, lvl)
    n = t["rows"]
    terms = {
        "load": 2 * vec * n if lvl == 0 else 0,  # r0 read, the finest b written
        # first sweep: b, dinv6, free, the slot starts and mids read, x written (its
        # zeroing just before, a part's rows at a time, stays in the cache); its
        # residual: free, the slot mids and stops read, r written
        "down_rows": (n * (t["firsts"] + dinv + free + 2 * vec)
                      + n * (t["lasts"] + free + vec)),
        "down_slots": t["full"] * t["full_slot"] + t["scalar"] * t["scalar_slot"],
        "down_gather": (t["full"] + t["scalar"]) * vec,
        "restrict": 0, "prolong": 0,
        # backward sweep: b, dinv6, free, the slot ends read; x read and written
        "up_rows": n * (t["ends"] + dinv + free + vec + 2 * vec),
        "up_slots": t["full"] * t["full_slot"] + t["scalar"] * t["scalar_slot"],
        "up_gather": (t["full"] + t["scalar"]) * vec,
        # the finest sweep's product: diag6 read, w written
        "up_product": n * (_row_bytes(pk.diag6) + vec) if lvl == 0 else 0,
    }
    if levels > 1:
        coarse_rows = int(pk.voff[lvl + 2] - pk.voff[lvl + 1])
        # each coarse row gathers its children: its ptr read and b written; per child,
        # its row and weight and r read
        ptr, kid_rows, weights = pk.kids
        lo_c, hi_c = int(pk.voff[lvl + 1]), int(pk.voff[lvl + 2])
        entries = int(ptr[hi_c] - ptr[lo_c])
        terms["restrict"] = (coarse_rows * (ptr.itemsize + vec)
                             + entries * (kid_rows.itemsize + weights.itemsize + vec))
        # parents and free read, x read and written; the next level's x read once
        terms["prolong"] = n * (parents + free + 2 * vec) + coarse_rows * vec
    down = sum(terms[k] for k in ("load", "down_rows", "down_slots", "down_gather",
                                  "restrict"))
    up = sum(terms[k] for k in ("prolong", "up_rows", "up_slots", "up_gather",
                                "up_product"))
    return {"level": lvl, "rows": n, "slots": t["full"] + t["scalar"],
            "earlier_slots": t["full_early"] + t["scalar_early"], "down": down, "up": up,
            "terms": terms}


def working_set_bytes(pk: PackedLevels, vectors: int = 5) -> int:
    """Bytes of every array an iteration touches, each once: the packed levels' slots, row
    blocks, parents, children and vectors, and ``vectors`` finest-level vectors of the outer CG (x,
    r, z, p, q). Set against the last-level cache: a working set that fits there is not
    streamed from memory every iteration, and the achieved rate can pass the triad's."""
    arrays = [*pk.slots, *pk.kids, pk.diag6, pk.dinv6, pk.free, pk.parents, pk.b, pk.x, pk.r]
    return sum(int(a.nbytes) for a in arrays) + vectors * int(pk.voff[1]) * _row_bytes(pk.x)


def last_level_cache_bytes() -> int | None:
    """The largest CPU cache's size in bytes (Linux sysfs of cpu0), None where unknown."""
    best = None
    for size in Path("/sys/devices/system/cpu/cpu0/cache").glob("index*/size"):
        try:
            text = size.read_text().strip().upper()
        except OSError:
            continue
        scale = {"K": 2**10, "M": 2**20, "G": 2**30}.get(text[-1:], 1)
        digits = text.rstrip("KMG")
        if digits.isdigit():
            best = max(best or 0, int(digits) * scale)
    return best


def packing_bytes(pk: PackedLevels) -> int:
    """Bytes one solve's packing of the levels moves (PackedLevels.fill's pack_level): per
    row the system's diagonal block (3 x 3) and the row's vertex read, free read, diag6,
    dinv6 and bdiag6 written; per slot its pair index and the pair's 3 x 3 block read, the packed
    block written. The coarsening that makes the coarse systems is not counted."""
    comps = pk.x.shape[1]
    block = comps * comps * pk.diag6.itemsize  # a system's 3 x 3 float64 block
    fstart, _, fstop, _, frows, sstart, _, sstop, _, swts = pk.slots
    total = 0
    for lvl in range(pk.n_levels):
        lo, hi = int(pk.voff[lvl]), int(pk.voff[lvl + 1])
        order = pk.orderings[lvl].order
        total += (hi - lo) * (block + order.itemsize + _row_bytes(pk.free)
                              + _row_bytes(pk.diag6) + _row_bytes(pk.dinv6)
                              + _row_bytes(pk.bdiag6))
        for kind, start, stop, values in ((pk.full, fstart, fstop, frows),
                                          (pk.scal, sstart, sstop, swts)):
            slots, _ = _slot_counts(start, start, stop, lo, hi)
            index = kind.local[lvl][1].itemsize
            total += slots * (index + block + _row_bytes(values))
    return total


def first_guess_bytes(pk: PackedLevels, it: dict | None = None) -> dict:
    """Bytes of a solve's first residual and first guess (MultigridSolver._solve_packed,
    solvers.first_guess): the rows the pins reach found (touched_rows: free read, touched
    written); the residual S (b - A x) (b, free and touched read, r written; the product's
    bytes, prorated, on the touched rows only, as marked by the last solve: pk.touched).
    Then the guess the last solve took (pk.last_guess): the rigid motion's rows of X and q
    (positions and forces read, X and q written), its Galerkin system (bdiag6, free,
    touched, X, q and r read), the shift (X read, x read and written) and the residual anew
    over every row (b and free read, r written, a whole product); or the translation's two
    passes (bdiag6, free, touched and r read; then x and r read and written). Returns
    {"residual", "guess", "total", "gathers"} in bytes ("gathers": the neighbour-vector
    terms inside the residuals' products). it: `iteration_bytes(pk)` when the caller has
    it."""
    it = iteration_bytes(pk) if it is None else it
    n0 = int(pk.voff[1])
    vec, free = _row_bytes(pk.x), _row_bytes(pk.free)
    mark = _row_bytes(pk.touched)
    share = float(np.count_nonzero(pk.touched)) / max(n0, 1)
    residual = n0 * (free + mark) + n0 * (2 * vec + free + mark) + share * it["product"]
    gathers = share * it["gathers"]["product"]
    if pk.last_guess == "rigid":
        guess = (n0 * 4 * vec + n0 * (_row_bytes(pk.bdiag6) + free + mark + 3 * vec)
                 + n0 * 3 * vec + n0 * (2 * vec + free) + it["product"])
        gathers += it["gathers"]["product"]
    else:
        guess = (2 * n0 * (_row_bytes(pk.bdiag6) + free + mark + vec)
                 + n0 * (2 * vec + vec))
    return {"residual": residual, "guess": guess, "total": residual + guess,
            "gathers": gathers}


def tick_bytes_estimate(pk: PackedLevels, iterations: float, solves: float) -> dict:
    """Bytes the solver moves per tick: per solve, the packing of the levels, the first
    residual and guess (`first_guess_bytes`) and ``iterations`` iterations; ``solves``
    solves (substeps) per tick. Only the solve: the assembly (forces, Jacobians, the step's
    system), the coarsening, collisions and the coarsest factorisation are not counted.
    Returns {"packing", "first_guess", "per_solve", "per_tick"} in bytes, and
    "per_solve_min", "per_tick_min" without the neighbour gathers."""
    it = iteration_bytes(pk)
    packing = packing_bytes(pk)
    first = first_guess_bytes(pk, it)
    per_solve = packing + first["total"] + float(iterations) * it["iteration"]
    gathers = first["gathers"] + float(iterations) * it["gathers"]["iteration"]
    return {"packing": packing, "first_guess": first["total"], "per_solve": per_solve,
            "per_tick": float(solves) * per_solve, "per_solve_min": per_solve - gathers,
            "per_tick_min": float(solves) * (per_solve - gathers)}


# -- timing the kernels ------------------------------------------------------------------------
def time_iteration(pk: PackedLevels, coarse_solve=None, repeats: int = 30,
                   seed: int = 0) -> dict:
    """Median ms of each part of one iteration, the solver's kernels called on ``pk`` as
    MultigridSolver._solve_packed calls them, with a random finest-level residual:
    {"down", "coarse", "up", "outer", "vcycle", "iteration"}. coarse_solve: b (n_c, 3) ->
    x, the coarsest level's solve (None: not timed, 0 ms). Overwrites pk's scratch vectors
    b, x, r (a solve refills them); the caller's numba threads run the kernels."""
    n = int(pk.voff[1])
    lo_c = int(pk.voff[-2])
    free = pk.free[:n, None]
    rng = np.random.default_rng(seed)
    r = rng.standard_normal((n, 3)) * free
    x = np.zeros((n, 3))
    z = np.zeros((n, 3))
    w = np.zeros((n, 3))
    p = np.zeros((n, 3))
    q = np.zeros((n, 3))
    slots, fine = pk.slots, pk.fine_chunks
    times: dict[str, list[float]] = {k: [] for k in ("down", "coarse", "up", "outer")}
    for rep in range(int(repeats) + 1):  # the first round loads the kernels: not counted
        t0 = time.perf_counter()
        vcycle_down(pk.n_levels, pk.voff, pk.bounds, pk.chunks, slots, pk.dinv6, pk.free,
                    pk.kids, r, pk.b, pk.x, pk.r)
        t1 = t2 = time.perf_counter()
        if coarse_solve is not None and pk.n_levels > 1:
            pk.x[lo_c:] = coarse_solve(pk.b[lo_c:])
            t2 = time.perf_counter()
        vcycle_up(pk.n_levels, pk.voff, pk.bounds, pk.chunks, slots, pk.dinv6, pk.diag6,
                  pk.free, pk.parents, pk.b, pk.x, r, z, w)
        t3 = time.perf_counter()
        # beta 0.5 keeps p bounded; alpha 0 leaves x and r as they are, the same bytes moved
        direction_update(fine, z, w, 0.5, p, q)
        cg_update(fine, x, r, p, q, 0.0)
        t4 = time.perf_counter()
        if rep:
            for key, dt in (("down", t1 - t0), ("coarse", t2 - t1), ("up", t3 - t2),
                            ("outer", t4 - t3)):
                times[key].append(1e3 * dt)
    ms = {k: float(np.median(v)) for k, v in times.items()}
    ms["vcycle"] = ms["down"] + ms["coarse"] + ms["up"]
    ms["iteration"] = ms["vcycle"] + ms["outer"]
    return ms


# -- a walking tick's report ---------------------------------------------------------------------
def _coarse_solve(sim, levels: int):
    """The coarsest level's solve for the simulator's next step (solvers.multigrid's
    CoarseSolver of the solver's own coarsening), or None. The pinned particles' penalty the
    solver adds is left out: it changes a few diagonal values, not the factor's size or the
    solve's work."""
    if levels < 2:
        return None
    step = assemble_step(sim.model, sim.state, sim.dt, sim.scheme, sim.control)
    return CoarseSolver(sim.solver.coarsening.coarsen(step.system)[-1]).solve


def _row(part: str, nbytes: float, gathers: float, ms: float, triad: float | None,
         timed: str = "kernels") -> dict:
    """One part's figures (`measure_traffic`'s rows): MB counted, "mb_min" without its
    neighbour gathers, ms, GB/s of the full count over ms, its fraction of the triad's
    (None where ``triad`` is None: a wall time that holds uncounted work) and ``timed``,
    what ms measured."""
    gbs = nbytes / (1e-3 * ms) / GB if ms > 0 else float("nan")
    return {"part": part, "mb": nbytes / MB, "mb_min": (nbytes - gathers) / MB, "ms": ms,
            "gbs": gbs, "of_triad": None if triad is None else gbs / triad, "timed": timed}


def measure_traffic(sim, run: dict, threads: int, repeats: int = 30,
                    stream_mb: int = 256) -> dict | None:
    """The memory-traffic figures of a simulator ``sim`` (sim.integrator.Simulator) whose
    solver has just run (a multigrid with packed levels: its ``_packed``; None otherwise):
    bytes per part (`iteration_bytes`), their measured times (`time_iteration`, on
    ``threads`` threads), achieved GB/s and its fraction of the triad bandwidth
    (`stream_bandwidth`); per solve and per tick from ``run`` (bench.walking.replay's
    medians: iterations per solve, substeps, ms per solve, ms per tick).

    Returns {"threads", "triad_gbs", "copy_gbs", "rows", "bytes" (`iteration_bytes`), "ms"
    (`time_iteration`), "tick_bytes" (`tick_bytes_estimate`, None without the run's
    iterations and substeps), "working_set_mb", "llc_mb"}. Each row: {"part", "mb", "mb_min"
    (MB = 1e6 B, without the neighbour gathers), "ms", "gbs" (mb over ms, GB/s = 1e9 B/s),
    "of_triad", "timed"}. The iteration's parts are timed on their kernels alone ("timed":
    "kernels"); the solve's and the tick's rows hold the bytes of the solver's iterations,
    packing and first guess over the run's median wall time of a whole solve (with its
    coarsening and set-up, "solve wall") or tick (with everything else, "tick wall"): an
    average over work partly uncounted, so their "of_triad" is None."""
    pk = getattr(sim.solver, "_packed", None)
    if pk is None:
        return None
    count = use_threads(threads)
    it = iteration_bytes(pk)
    ms = time_iteration(pk, _coarse_solve(sim, pk.n_levels), repeats)
    stream = stream_bandwidth(count, stream_mb)
    triad = stream["triad_gbs"]
    down = sum(lv["down"] for lv in it["levels"])
    up = sum(lv["up"] for lv in it["levels"]) + it["take"]
    g = it["gathers"]
    rows = [_row("V-cycle down (sweeps, restriction)", down, g["down"], ms["down"], triad),
            _row("coarsest solve (b, x only)", it["coarse"], 0, ms["coarse"], triad),
            _row("V-cycle up (prolongation, sweeps)", up, g["up"], ms["up"], triad),
            _row("V-cycle", it["vcycle"], g["down"] + g["up"], ms["vcycle"], triad),
            _row("outer (p, q, x, r)", it["outer"], 0, ms["outer"], triad),
            _row("CG iteration", it["iteration"], g["iteration"], ms["iteration"], triad)]
    llc = last_level_cache_bytes()
    its, solves = run.get("iterations"), run.get("substeps")
    tick = None
    if its is not None and solves:
        tick = tick_bytes_estimate(pk, its, solves)
        # the run times whole solves and ticks, not the counted kernels alone
        rows.append(_row("solve: its bytes over a whole solve's time", tick["per_solve"],
                         tick["per_solve"] - tick["per_solve_min"], run["ms_per_solve"], None,
                         "solve wall"))
        rows.append(_row("tick: its solves' bytes over the tick's time", tick["per_tick"],
                         tick["per_tick"] - tick["per_tick_min"], run["ms_per_tick"], None,
                         "tick wall"))
    return {"threads": count, "triad_gbs": triad, "copy_gbs": stream["copy_gbs"],
            "rows": rows, "bytes": it, "ms": ms, "tick_bytes": tick,
            "working_set_mb": working_set_bytes(pk) / MB,
            "llc_mb": None if llc is None else llc / MB}


def format_traffic(traffic: dict) -> str:
    """The printed table of `measure_traffic`'s figures."""
    head = (f"memory traffic (bytes counted / measured time; STREAM-like triad "
            f"{traffic['triad_gbs']:.1f} GB/s, copy {traffic['copy_gbs']:.1f} GB/s on "
            f"{traffic['threads']} threads)")
    llc = traffic.get("llc_mb")
    cache = f", largest cache {llc:.1f} MB" if llc else ""
    note = (f"MB counts each neighbour's vector once per slot (an upper bound), 'MB min' "
            f"none; working set {traffic['working_set_mb']:.1f} MB{cache}")
    rows = [[r["part"], f"{r['mb']:.2f}", f"{r['mb_min']:.2f}", f"{r['ms']:.3f}",
             f"{r['gbs']:.1f}",
             "-" if r.get("of_triad") is None else f"{100 * r['of_triad']:.0f} %"]
            for r in traffic["rows"]]
    lines = [head, note, "",
             text_table(["part", "MB", "MB min", "ms", "GB/s", "of triad"], rows)]
    if any(r.get("timed", "kernels") != "kernels" for r in traffic["rows"]):
        lines.append("solve, tick: the solver's counted bytes over the run's median wall "
                     "time of a whole solve (coarsening, set-up) or tick (assembly, "
                     "collisions), whose bytes are not counted: an average rate, not set "
                     "against the triad")
    return "\n".join(lines)
