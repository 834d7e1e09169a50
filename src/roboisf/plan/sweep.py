"""Evaluate many placements, serially, on threads of this process or on a Dask cluster, and rank
them.

Threads (``scheduler="threads"``, the default with the compiled engine): the path kernels of
:mod:`roboisf.robot.ik_numba` run without the GIL when called from a thread other than the main
one, and a placement's Python bookkeeping is ~1 % of its time, so ``n_workers`` threads keep as
many cores busy with no process start, no pickling and no copy of the problem; each thread runs
the serial code on the same inputs (bit-for-bit the serial scores, tested).

Dask layout: the :class:`PlanProblem` (toolpath, wrench, robot — the big, shared part) is
scattered to every worker once; each task carries a batch of placements (a (B, 4, 4) array) and
the tool-rotation candidates, and returns their scores. Tasks run the same numpy code as the
serial path on the same inputs, so the scores are bit-for-bit those of the serial run (tested).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError, UnreachableError
from roboisf.jit import cores
from roboisf.plan.evaluate import (
    PlacementScore,
    _evaluate_many,
    _kernel_inputs,
    evaluate_batch,
    evaluate_placement,
    path_sigma_min,
)
from roboisf.plan.problem import PlanProblem, placement_transforms
from roboisf.progress import Progress, task
from roboisf.robot.vjm_kernel import single_blas_thread

__all__ = ["WORKER_ENV", "PlanResult", "default_scheduler", "plan_placements"]

F64 = NDArray[np.float64]

#: Environment of the local cluster's worker processes. Dask's default trims the heap at 64 KiB
#: (``MALLOC_TRIM_THRESHOLD_``), so every multi-MB temporary of a 20k-point evaluation is mmapped
#: and page-faulted afresh: measured 1.7× slower per placement. Keeping large blocks on the heap
#: removes the faults (0 minor faults per placement instead of ~30,000). Single-threaded BLAS as
#: in Dask's default. Set the same variables on the workers of an external cluster.
WORKER_ENV = {
    "MALLOC_TRIM_THRESHOLD_": 268435456,
    "MALLOC_MMAP_THRESHOLD_": 134217728,
    "OMP_NUM_THREADS": 1,
    "MKL_NUM_THREADS": 1,
    "OPENBLAS_NUM_THREADS": 1,
}


@dataclass(frozen=True, eq=False)
class PlanResult:
    """Scores of every candidate placement, ranked.

    placements : (M, 4) float — [x, y, z, yaw] (m, rad), T_base_work of the work frame
    scores : list of M :class:`PlacementScore`, in the order of ``placements``
    order : (K,) int — indices of the feasible candidates, best first
    tool_rotations : (G,) float, rad — the γ candidates
    baseline : PlacementScore or None — the reference placement (e.g. the paper-like cell)
    baseline_T : (4, 4) or None
    objective : str
    notes : list of str — e.g. "γ has no effect: coaxial tool"
    best_gamma0 : PlacementScore or None — the best placement with the tool at γ = 0 (set when
        several tool rotations were evaluated: what the rotation adds to the placement)
    """

    placements: F64
    scores: list[PlacementScore]
    order: NDArray[np.intp]
    tool_rotations: F64
    baseline: PlacementScore | None
    baseline_T: F64 | None
    objective: str
    notes: list[str]
    best_gamma0: PlacementScore | None = None

    @property
    def best(self) -> PlacementScore:
        return self.scores[int(self.order[0])]

    @property
    def best_placement(self) -> F64:
        """(4,) [x, y, z, yaw] of the best candidate (m, rad)."""
        return self.placements[int(self.order[0])]

    def improvement(self, field: str = "mean_robot") -> float:
        """Relative reduction of ``field`` from the baseline to the best candidate (0.25 = 25 %)."""
        if self.baseline is None or not self.baseline.ok:
            return math.nan
        b = getattr(self.baseline, field)
        return float((b - getattr(self.best, field)) / b)

    def rejected(self) -> dict[str, int]:
        """Count of candidates per non-ok status."""
        out: dict[str, int] = {}
        for s in self.scores:
            if not s.ok:
                out[s.status] = out.get(s.status, 0) + 1
        return out

    def table(self) -> list[dict[str, Any]]:
        """One row per candidate, ranked ones first (rank 1 = best), then the rejected ones.

        Units: mm and degrees (for files and screens).
        """
        rank = {int(i): r + 1 for r, i in enumerate(self.order)}
        idx = list(self.order) + [i for i in range(len(self.scores)) if i not in rank]
        rows = []
        for i in idx:
            s, p = self.scores[int(i)], self.placements[int(i)]
            g = s.gamma
            rows.append(
                {
                    "rank": rank.get(int(i), ""),
                    "x_mm": p[0] * 1e3,
                    "y_mm": p[1] * 1e3,
                    "z_mm": p[2] * 1e3,
                    "yaw_deg": math.degrees(p[3]),
                    "status": s.status,
                    "mean_abs_mm": s.mean_abs * 1e3,
                    "max_abs_mm": s.max_abs * 1e3,
                    "mean_abs_normal_mm": s.mean_abs_normal * 1e3,
                    "mean_robot_mm": s.mean_robot * 1e3,
                    "max_robot_mm": s.max_robot * 1e3,
                    "sigma_min": s.sigma_min,
                    "max_joint_step_deg": math.degrees(s.max_joint_step),
                    "gamma_first_deg": math.nan if g is None else math.degrees(g[0]),
                    "gamma_min_deg": math.nan if g is None else math.degrees(g.min()),
                    "gamma_max_deg": math.nan if g is None else math.degrees(g.max()),
                    "reason": s.reason,
                }
            )
        return rows


def default_scheduler(problem: PlanProblem, cpus: int | None = None) -> str:
    """ "threads" when the placements run on the compiled engine (GIL-free) or on at most two
    CPUs, else "local" (Dask processes: the numpy engine holds the GIL for much of a
    placement). ``cpus``: the CPUs this process may use (default: its affinity).

    Two CPUs, the numpy engine (a new install's first `plan`, its kernels not built yet): the
    cone's default grid took 10.5–13.2 s on two threads against 11.9–15.8 s on a Dask cluster
    of two processes, whose start and second import of roboisf cost more than the GIL does
    (2 vCPUs, 2026-11-28, two runs each, alternated)."""
    from roboisf.robot import vjm_kernel

    compiled = vjm_kernel.use_numba(problem.model.backend) and problem.model.stiffness is not None
    n = cores() if cpus is None else cpus
    return "threads" if compiled or n <= 2 else "local"


def _thread_map(
    problem: PlanProblem,
    Ts: F64,
    g: F64,
    n_workers: int | None,
    batch_size: int | None,
    advance: Any,
) -> list[PlacementScore]:
    """:func:`evaluate_batch` over batches of placements on ``n_workers`` threads (default: the
    CPUs this process may use), the results in placement order."""
    from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

    nw = n_workers or cores()
    m = Ts.shape[0]
    # small batches: threads cost nothing to feed, and the last batches finish together
    size = batch_size or max(1, min(8, math.ceil(m / (4 * nw))))
    _kernel_inputs(problem)  # the shared kernel inputs made once, before the threads start
    results: list[PlacementScore | None] = [None] * m
    # BLAS pinned once for the whole pool (threadpoolctl's limits are process-wide)
    with single_blas_thread(), ThreadPoolExecutor(nw, thread_name_prefix="roboisf-plan") as ex:
        pending = {ex.submit(_evaluate_many, problem, Ts[sl], g): sl for sl in _batches(m, size)}
        try:
            while pending:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for fut in done:
                    sl = pending.pop(fut)
                    results[sl] = fut.result()
                    advance(sl.stop - sl.start)
        finally:
            for fut in pending:  # an error or Ctrl-C: do not start the rest
                fut.cancel()
    out = [r for r in results if r is not None]
    assert len(out) == m
    return out


def _batches(n: int, size: int) -> list[slice]:
    return [slice(s, min(n, s + size)) for s in range(0, n, size)]


def plan_placements(
    problem: PlanProblem,
    placements: ArrayLike,
    tool_rotations: ArrayLike = (0.0,),
    *,
    baseline: ArrayLike | None = None,
    scheduler: str | Any | None = "auto",
    n_workers: int | None = None,
    batch_size: int | None = None,
    detail: int = 20,
    progress: Progress | None = None,
) -> PlanResult:
    """Score candidate placements (M, 4) ``[x, y, z, yaw]`` (m, rad) over tool rotations (G,) rad.

    ``scheduler``: ``"auto"`` (default: ``"threads"`` with the compiled engine, else
    ``"local"``), ``"threads"`` (``n_workers`` threads of this process, default one per usable
    CPU; the compiled kernels run without the GIL), ``"serial"`` (this process), ``"local"`` (a Dask
    ``LocalCluster`` of ``n_workers`` single-threaded worker processes, default 2, started and
    closed here), an address ``"tcp://host:8786"`` of a running Dask scheduler, or a
    ``dask.distributed.Client``. Every scheduler gives the serial run's scores bit for bit.
    ``baseline``: a reference ``T_base_work`` (4, 4) scored at γ = 0 (e.g. the current cell).
    ``detail``: for the best ``detail`` candidates and the baseline, the value of σ_min along the
    path is computed (all feasible candidates passed the exact margin test).

    A round part (``problem.symmetry`` continuous) is the same part at any yaw: rows that differ
    in yaw alone are evaluated once (the first; with a tool off axis 6 the others' yaws become
    tool rotations), and ``notes`` says so — the result's ``placements`` are those evaluated.

    Raises :class:`~roboisf.errors.UnreachableError` when no candidate is feasible (the message
    gives the reasons); infeasible candidates are otherwise kept in ``scores`` with their reason.
    """
    P, g, notes = evaluated_candidates(problem, placements, tool_rotations)
    Ts = placement_transforms(P)
    if n_workers is not None and n_workers < 1:
        raise InputError(f"must be ≥ 1, got {n_workers}", field="workers")
    if batch_size is not None and batch_size < 1:
        raise InputError(f"must be ≥ 1, got {batch_size}", field="batch size")
    m = Ts.shape[0]
    if isinstance(scheduler, str) and scheduler == "auto":
        scheduler = default_scheduler(problem)
    scores: list[PlacementScore] = []
    with task(progress, f"placements ({m} × {g.size} tool rotations)", m) as advance:
        if isinstance(scheduler, str) and scheduler == "threads":
            scores = _thread_map(problem, Ts, g, n_workers, batch_size, advance)
        elif scheduler is None or scheduler == "serial":
            for sl in _batches(m, batch_size or 8):
                scores.extend(evaluate_batch(problem, Ts[sl], g))
                advance(sl.stop - sl.start)
        else:
            scores = _dask_map(problem, Ts, g, scheduler, n_workers, batch_size, advance)
    base = base_T = None
    if baseline is not None:
        base_T = np.asarray(baseline, dtype=float)
        if base_T.shape != (4, 4):
            raise InputError(f"expected a (4, 4) transform, got {base_T.shape}", field="baseline")
        base = evaluate_placement(problem, base_T, (0.0,))
    key = np.array([s.objective(problem.objective) for s in scores])
    ok = np.flatnonzero(np.isfinite(key))
    if ok.size == 0:
        reasons = sorted({f"{s.status}: {s.reason}" for s in scores})
        raise UnreachableError(
            f"none of the {m} candidate placements is feasible; e.g. "
            + " | ".join(reasons[:3])
            + (f" (and {len(reasons) - 3} more reasons)" if len(reasons) > 3 else ""),
            indices=list(range(m)),
        )
    order = ok[np.argsort(key[ok], kind="stable")]
    if detail < 0:
        raise InputError(f"must be ≥ 0, got {detail}", field="detail")
    for i in order[:detail]:
        s = scores[int(i)]
        assert s.gamma is not None
        scores[int(i)] = replace(s, sigma_min=path_sigma_min(problem, Ts[int(i)], s.gamma))
    if base is not None and base.ok:
        assert base.gamma is not None and base_T is not None
        base = replace(base, sigma_min=path_sigma_min(problem, base_T, base.gamma))
    best0 = None
    if g.size > 1:
        best0 = evaluate_placement(problem, Ts[int(order[0])], (0.0,))
    return PlanResult(P, scores, order, g, base, base_T, problem.objective, notes, best0)


def evaluated_candidates(
    problem: PlanProblem, placements: ArrayLike, tool_rotations: ArrayLike = (0.0,)
) -> tuple[F64, F64, list[str]]:
    """The placements (M, 4) and tool rotations (G,) :func:`plan_placements` evaluates for
    ``placements`` × ``tool_rotations``, and the notes that say why they differ: one γ for a
    tool coaxial with axis 6, one yaw per x, y, z for a round part (its other yaws as tool
    rotations when the tool is off axis 6). Cheap: no pose is evaluated."""
    P = np.asarray(placements, dtype=float)
    placement_transforms(P)  # the shape and values checked
    g = np.atleast_1d(np.asarray(tool_rotations, dtype=float))
    if g.ndim != 1 or g.size == 0 or not np.all(np.isfinite(g)):
        raise InputError(
            f"expected at least one finite tool rotation, got {g.size}", field="tool rotations"
        )
    notes: list[str] = []
    coaxial = problem.tool_is_coaxial()
    if g.size > 1 and coaxial:
        notes.append(
            "the tool is coaxial with axis 6 and its compliance is axisymmetric: turning it about "
            "its own axis only turns A6 and cannot change the deflection; evaluated γ = "
            f"{math.degrees(g[0]):g}° only"
        )
        g = g[:1]
    if problem.symmetry.continuous:
        P, g = _one_yaw_of_a_round_part(P, g, coaxial, notes)
    return P, g, notes


def _one_yaw_of_a_round_part(P: F64, g: F64, coaxial: bool, notes: list[str]) -> tuple[F64, F64]:
    """Placements (M, 4) and tool rotations (G,) of a part that is a surface of revolution about
    the work z axis, with the candidates that differ in yaw alone evaluated once.

    Turned about its axis, such a part is the same part: the same toolpath points under the same
    forces, only the laps start elsewhere (the mean |δ| equal to ≤ 1e-9 relative, the max |δ| to
    the path's sampling: docs/plan.md). Each x, y, z keeps its first row, with its
    yaw. With a tool that is not coaxial with axis 6 the yaw still turns the tool relative to the
    robot: ``Rz(ψ)·Rx(π)·Rz(γ) = Rx(π)·Rz(γ − ψ)``, so a yaw ψ + Δψ left out is searched as the
    tool rotations γ − Δψ of the row kept. A note says what was done.
    """
    _, first, inv = np.unique(P[:, :3], axis=0, return_index=True, return_inverse=True)
    if first.size == P.shape[0]:
        return P, g
    dyaw = P[:, 3] - P[first[inv.reshape(-1)], 3]  # each row's yaw from its kept row's
    keep = P[np.sort(first)]
    yaws = ", ".join(f"{math.degrees(v):g}°" for v in np.unique(keep[:, 3]))
    note = (
        "yaw: the part is round (turned about its axis it gives the same toolpath points under "
        "the same forces; only the laps start elsewhere)"
    )
    if coaxial:
        note += (
            f", so its yaw does not change the deflection: evaluated yaw {yaws} only "
            f"({P.shape[0]} → {keep.shape[0]} placements)"
        )
    else:
        cand = np.concatenate([g, (g[None, :] - np.unique(dyaw)[:, None]).ravel()])
        _, idx = np.unique(np.round(np.mod(np.degrees(cand), 360.0), 9) % 360.0, return_index=True)
        g = cand[np.sort(idx)]
        note += (
            "; with this tool (not coaxial with axis 6) a yaw ψ only turns the tool by −ψ about "
            f"its own axis relative to the robot: evaluated yaw {yaws} only ({P.shape[0]} → "
            f"{keep.shape[0]} placements), the other yaws as tool rotations (γ = "
            + ", ".join(f"{math.degrees(v):g}°" for v in g)
            + ")"
        )
    notes.append(note)
    return keep, g


def _refuse_fast(address: str) -> None:
    """Raise ``ConnectionRefusedError`` at once when nothing listens at a ``tcp://host:port``
    (or ``host:port``) scheduler address; Dask's client would retry a refused connection until
    its 10 s timeout. Other failures (no route, a slow host, other protocols) are left to Dask."""
    import socket
    from urllib.parse import urlsplit

    if "://" in address and not address.startswith("tcp://"):
        return
    try:
        u = urlsplit(address if "://" in address else f"tcp://{address}")
        host, port = u.hostname, u.port
    except ValueError:
        return
    if not host or port is None:
        return
    try:
        socket.create_connection((host, port), timeout=2.0).close()
    except ConnectionRefusedError:
        raise
    except OSError:
        return  # not a definite refusal: Dask decides, with its own timeout


def _dask_map(
    problem: PlanProblem,
    Ts: F64,
    g: F64,
    scheduler: str | Any,
    n_workers: int | None,
    batch_size: int | None,
    advance: Any,
) -> list[PlacementScore]:
    import dask
    from dask.distributed import Client, LocalCluster, as_completed

    own: list[Any] = []
    try:
        if isinstance(scheduler, Client):
            client = scheduler
        elif scheduler == "local":
            with dask.config.set({"distributed.nanny.pre-spawn-environ": WORKER_ENV}):
                cluster = LocalCluster(
                    n_workers=n_workers or 2,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=None,
                )
            own.append(cluster)
            client = Client(cluster)
            own.append(client)
        elif isinstance(scheduler, str):
            try:
                _refuse_fast(scheduler)
                client = Client(scheduler, timeout=10)
            except OSError as e:
                raise InputError(
                    f"cannot reach the Dask scheduler at {scheduler!r}: {e}", field="--scheduler"
                ) from None
            except ValueError as e:  # Dask's address parser: no port, an unknown protocol
                raise InputError(
                    f"expected 'threads', 'local' or a Dask scheduler address such as "
                    f"tcp://host:8786, got {scheduler!r} ({e})",
                    field="--scheduler",
                ) from None
            own.append(client)
        else:
            raise InputError(
                f"expected 'serial', 'local', a scheduler address or a Client, got {scheduler!r}",
                field="scheduler",
            )
        nw = max(1, len(client.scheduler_info().get("workers", {})) or (n_workers or 1))
        m = Ts.shape[0]
        # a few tasks per worker for load balance; a task long enough to hide the overhead
        size = batch_size or max(1, min(64, math.ceil(m / (4 * nw))))
        shared = client.scatter(problem, broadcast=True)
        futures = {}
        for sl in _batches(m, size):
            fut = client.submit(evaluate_batch, shared, Ts[sl], g, pure=False)
            futures[fut] = sl
        results: list[PlacementScore | None] = [None] * m
        for fut in as_completed(futures):
            sl = futures[fut]
            results[sl] = fut.result()
            advance(sl.stop - sl.start)
        out = [r for r in results if r is not None]
        assert len(out) == m
        return out
    finally:
        for obj in reversed(own):
            obj.close()
