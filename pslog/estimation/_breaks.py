"""Batched search for the instant of a velocity jump (a bounce or a kick).

For a candidate near ``t_c``, the reprojection problem linearised at the current fit
(``J_i X ≈ z_i`` per detection, weights ``w_i / σ²``) is solved on a local window under the
motion prior: a spline that is C² everywhere on uniform knots ``t_c + k·h`` (the *base*, one
small dense solve per candidate, all candidates in one batched call; the prior's normal matrix
is shift invariant and computed once). A break at a trial instant ``τ`` in span
``[u_j, u_{j+1})`` inserts a triple knot at ``τ`` into those knots; the spline space then is
the base space plus the three cubic B-splines on knots ``(u_{j-1}, u_j, τ, τ, τ)``,
``(u_j, τ, τ, τ, u_{j+1})`` and ``(τ, τ, τ, u_{j+1}, u_{j+2})`` (they live on three spans;
none of their combinations is C² at ``τ``, so they add exactly the three new dimensions). With
``y`` their coefficients (9 unknowns), ``x`` the base control points, the base minimum ``x₀``
and its inverse information ``Σ = H⁻¹``, the least cost with the break is, exactly,

    cost_with(τ) = cost_base - gᵀ S⁻¹ g,   S = H_yy - H_yx Σ H_xy,   g = -½ ∂cost/∂y at (x₀, 0)

(the Schur complement of the base unknowns; ``H_xy`` touches only the six base control points
over those three spans, so only a 18 x 18 block of ``Σ`` is needed). The prior terms of
``H_yy``, ``H_xy`` and ``g`` are integrated exactly on the four sub-spans around ``τ`` (2-point
Gauss for ``p''``, midpoint for ``p'''``, as everywhere). So a trial instant costs a 9 x 9
solve, and every (candidate, τ) pair of a scan stage is one batched call. The B-spline on
``(u_{j-1}, u_j, τ, τ, τ)`` degenerates as ``τ → u_j`` (and ``S`` with it), so every candidate
has two bases, on knots ``t_c + k·h`` and ``t_c + h/2 + k·h``, and a trial instant is tested
on the one whose knots are at least ``h/4`` from it (as the final knots keep no uniform knot
within ``h/4`` of a break). The gain of the break is the cost of the base on ``t_c + k·h``
minus the least cost with it (a likelihood ratio in units of σ²), i.e. ``gᵀ S⁻¹ g`` plus the
difference of the two bases' costs when the shifted one is used.

``τ`` is found by a grid of 7 trial instants over the bounds, then two stages of three
trials ``v - d, v, v + d`` (``v`` the vertex of the parabola through the previous stage's
best three, ``d`` a quarter of the previous step), then one at the last vertex: 14 trials,
the best of them wins. The gain is a smooth function of ``τ`` between detection times (a
kink at each) and broad: a bounce's gain falls by one σ² (one standard deviation of ``τ``)
a few milliseconds from its peak, so vertices of parabolas through trials a few ms apart
find the peak to well below that. A refinement (:func:`scan_near`, a break located already)
searches a quarter spacing around it: every trial instant there is at least ``h/4`` from the
knots ``t_c + h/2 + k·h``, so one base serves, and a grid of 5 with the same two stages and
final trial makes 12 trials; where the grid's best was at an end of the quarter spacing, the
caller searches the whole spacing again (:func:`scan`). Since session 23 the refinement
searches ``h/16`` either side of the break first (``scan_near(..., narrow=True)``: a grid of
3, one polishing stage, the final trial: 7 trials; the breaks move by a median of 0.4 ms,
1.2 % of ``h``, between the loose fit and the final one), and the quarter spacing only for
the ~10 % whose grid's best was at an end of that.
"""

from __future__ import annotations

from collections.abc import Iterator
from functools import cache, lru_cache

import numpy as np

from .bspline import basis, clamped_knots, n_control

_GRID = 7  # trial instants of a scan's first stage
_NEAR_GRID = 5  # of a refinement's (:func:`scan_near`)
_POLISH = 2  # stages of three trials around the last parabola's vertex
#: a narrow refinement's (:func:`scan_near` with ``narrow``): a grid of 3 over the bounds
#: (``h/16`` either side of the break), then this many polishing stages
_NARROW_POLISH = 1
_BATCH = 2000  # (candidate, τ) pairs per batched solve: bounds memory
#: candidates per block of the scan: their local problems (two 3m x 3m matrices each) stay
#: in cache, where a whole session's at once (20,000 windows at 90 minutes) took 500 MB
_BLOCK = 128
#: blocks a scan needs before it takes a second thread: a thread's start, its fresh malloc
#: arena (faulted in page by page: ~2,800 faults in a 2-minute fit's first call) and the
#: pool's import cost ~5-10 ms of CPU, about a block's work, while a scan of 2 or 3 blocks
#: (a session of a few minutes) saves at most a block or so of wall time
_THREAD_BLOCKS = 4


def smooth_threads() -> int:
    """Threads of the break scan (``PSLOG_SMOOTH_THREADS``, default 2, at most the CPUs this
    process may use; 1 forces one): blocks of candidates are independent problems, each
    written to its own place, so the result is the same bits on any number."""
    import os

    text = os.environ.get("PSLOG_SMOOTH_THREADS", "").strip()
    # (a count of more digits than int() parses, 4300, is a whole number all the same:
    # clamped to the CPUs as any large count is)
    huge = text.isascii() and text.isdigit() and len(text.lstrip("0")) > 9
    try:
        wanted = 2 if not text else 2**31 if huge else int(text)
    except ValueError:
        wanted = 0
    if wanted < 1:
        from ..errors import PslogError

        raise PslogError(f"PSLOG_SMOOTH_THREADS must be a whole number >= 1, got {text!r}")
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cpus = os.cpu_count() or 1
    return max(1, min(wanted, cpus))


def scan_threads(blocks: int) -> int:
    """Threads of a scan of ``blocks`` blocks of candidates: :func:`smooth_threads`, at
    most one per block, and one below ``_THREAD_BLOCKS`` blocks (the same bits on any
    number: each block's result lands in its own place)."""
    threads = smooth_threads()  # (a bad PSLOG_SMOOTH_THREADS is an error whatever the size)
    return 1 if blocks < _THREAD_BLOCKS else min(threads, blocks)


def on_threads(fn, jobs: list, threads: int) -> list:
    """``[fn(*job) for job in jobs]`` on this thread and ``threads - 1`` more, each taking
    the next job not yet taken; each result in its job's place. The calling thread works
    too (a pool's workers would leave it waiting): one thread started fewer, and its
    allocations come from this thread's malloc arena, whose freed memory the fit keeps
    (:mod:`pslog.estimation._memory`), not from a new thread's fresh one. The first
    exception of any job is raised once every thread has stopped (none starts a new job
    after it)."""
    import threading

    results: list = [None] * len(jobs)
    errors: list[BaseException] = []
    lock = threading.Lock()
    taken: Iterator[int] = iter(range(len(jobs)))

    def work() -> None:
        while True:
            with lock:
                i = None if errors else next(taken, None)
            if i is None:
                return
            try:
                results[i] = fn(*jobs[i])
            except BaseException as exc:  # raised below, on the calling thread
                with lock:
                    errors.append(exc)
                return

    helpers = [threading.Thread(target=work, name=f"pslog-smooth-scan-{k + 1}", daemon=True)
               for k in range(threads - 1)]
    for helper in helpers:
        helper.start()
    try:
        work()
    finally:
        with lock:
            if not errors:  # (an interrupt of this thread: the helpers take no more jobs)
                taken = iter(())
        for helper in helpers:
            helper.join()
    if errors:
        raise errors[0]
    return results


_GAUSS = 1 / np.sqrt(3.0)
_ACCEL = np.arange(12) < 8  # of the 12 prior nodes: p'' at the Gauss nodes, the jerk at mids


class _Local:
    """A local knot pattern in units of the spacing ``h``: ``k = -K..K``, the middle knot of
    multiplicity 3 (break) or 1 (no break), with the prior's dense normal equations."""

    def __init__(self, K: int, spacing: float, prior, multiplicity: int):
        from .trajectory import _prior_normal  # the one prior (2) of the trajectory module

        breaks = np.arange(-K, K + 1, dtype=np.float64)
        mult = np.ones(len(breaks) - 2, dtype=np.int64)
        mult[K - 1] = multiplicity
        self.knots = clamped_knots(breaks, mult)
        self.m = n_control(self.knots)
        self.K = K
        ab, rhs, const, _ = _prior_normal([spacing * self.knots], np.zeros(1, np.int64), self.m,
                                       prior)
        n = 3 * self.m
        P = np.zeros((n, n))
        for d in range(12):
            i = np.arange(n - d)
            P[i, i + d] = ab[11 - d, d:]
            P[i + d, i] = ab[11 - d, d:]
        self.P, self.rhs, self.const = P, rhs, const


@lru_cache(maxsize=16)
def _local(K: int, spacing: float, prior, multiplicity: int) -> _Local:
    return _Local(K, spacing, prior, multiplicity)


class _Base:
    """The no-break local problems of a batch of windows (``local``; ``t, J, z, w`` (n,),
    (n, 2, 3), (n, 2), (n,) the detections' times (s), Jacobians, linearised targets and
    weights already divided by σ²; ``index``, ``valid`` (B, W) each window's detections and
    padding; ``centre`` (B,) s, the middle knot; ``spans`` the lowest and highest span
    ``j`` (in spacings from the centre) a trial instant may fall in): their minimum ``x0``
    (B, m, 3), the columns ``col0..`` of the inverse information that the 18 x 18 blocks
    of those spans' six control points read, ``cov`` (B, 3m, c), minimum cost, and per
    detection the basis (``first`` (B, W), ``N`` (B, W, 4)), ``M = w JᵀJ`` (B, W, 3, 3) and
    the weighted residual ``u = w Jᵀ (z - J X₀)`` (B, W, 3) at the minimum. Without
    ``spans`` every column of the inverse is kept. ``terms``: :func:`detection_terms` of the
    detections the windows read (None: made here), each detection's ``w J`` and ``w JᵀJ``
    formed once, not once per window and base that holds it."""

    def __init__(self, local, t, J, z, w, index, valid, centre, spacing, spans=None,
                 terms=None):
        B, W = index.shape
        s = (t[index] - centre[:, None]) / spacing
        inside = valid & (np.abs(s) < local.K - 1e-9)
        s = np.where(inside, s, 0.0)
        first, N = basis(local.knots, s.ravel(), 0)
        first = first.reshape(B, W)
        N = N[:, 0].reshape(B, W, 4)
        m = local.m
        n = 3 * m
        if terms is None:
            terms = detection_terms(J, w, np.zeros(0, np.int64), np.zeros(0, np.int64))
        at, wJ_all, M_all = terms
        # w JᵀJ (B, W, 3, 3) and w Jᵀ z (B, W, 3) of the detections inside (their rows in
        # the terms), w ‖z‖² (B, W); the rest, padding, zero (no term reads them): one
        # compiled gather (:func:`pslog.estimation._window.window_terms`)
        from ._window import window_terms

        self.M, v, wz = window_terms(
            np.ascontiguousarray(index, dtype=np.int64), np.ascontiguousarray(inside),
            np.ascontiguousarray(at, dtype=np.int64), np.ascontiguousarray(wJ_all),
            np.ascontiguousarray(M_all), np.ascontiguousarray(z, dtype=np.float64),
            np.ascontiguousarray(w, dtype=np.float64))
        # only the inverse's columns the gains read (a solve for them and the minimum is
        # cheaper than the whole inverse)
        lo, hi = 0, n
        if spans is not None:
            lo = int(np.clip(3 * (spans[0] + local.K - 1), 0, n - 18))
            hi = int(np.clip(3 * (spans[1] + local.K - 1) + 18, lo + 18, n))
        # H = P + Σ_w (b_w b_wᵀ) ⊗ M_w, each detection's 12 x 12 block where its four
        # control points are (a compiled loop: the dense products of the basis matrix cost
        # m / 4 times more), its diagonal times 1 + 1e-12 (keeps a degenerate window
        # solvable), factored and solved: one window at a time in one compiled pass
        from ._kernels import window_normal, window_normal_solve

        args = (np.ascontiguousarray(N), np.ascontiguousarray(self.M),
                np.ascontiguousarray(v), inside)
        x, self.cov, ok, rhs = window_normal_solve(local.P, local.rhs, first, *args, lo, hi)
        self.col0 = lo
        if not np.all(ok):  # a pivot not positive (a degenerate window): LU there
            bad = np.flatnonzero(~ok)
            H, _ = window_normal(local.P, local.rhs, np.ascontiguousarray(first[bad]),
                                 *(np.ascontiguousarray(a[bad]) for a in args))
            H[:, np.arange(n), np.arange(n)] *= 1 + 1e-12
            unit = np.zeros((n, hi - lo + 1))
            unit[np.arange(lo, hi), np.arange(hi - lo)] = 1.0
            sol = np.linalg.solve(H, np.concatenate([np.broadcast_to(
                unit, (len(bad), n, hi - lo + 1))[..., :-1], rhs[bad][..., None]], axis=2))
            self.cov[bad], x[bad] = sol[..., :-1], sol[..., -1]
        self.cost = np.sum(wz, axis=1) + local.const - np.einsum("bk,bk->b", rhs, x)
        self.x0 = x.reshape(B, -1, 3)
        self.first, self.N = np.ascontiguousarray(first, dtype=np.int64), np.ascontiguousarray(N)
        from ._kernels import window_positions

        X0 = window_positions(self.first, self.N, np.ascontiguousarray(self.x0))  # (B, W, 3)
        from ._window import products_compiled, window_products

        # w Jᵀ (z - J X₀): M X₀ compiled where it gives numpy's matmul's bits
        MX = (window_products(self.M, X0) if products_compiled()
              else (self.M @ X0[..., None])[..., 0])
        self.u = v - MX
        self.s_sorted = np.where(inside, s, 1e6)  # times in spacings from the centre, sorted
        self.local, self.spacing = local, spacing


def detection_terms(J: np.ndarray, w: np.ndarray, i0: np.ndarray, i1: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each detection's ``w J`` (r, 2, 3) and ``w JᵀJ`` (r, 3, 3) (numpy's products, as
    :class:`_Base` formed them per window: the same bits) for the r detections that some
    window ``i0[c]..i1[c]-1`` holds (every detection when the windows are empty), and
    ``at`` (n,): a detection's row in them (0 for one no window holds). A detection lies in
    the windows of several candidates and in both bases of each: formed once here."""
    n = len(w)
    if len(i0):
        starts = np.bincount(i0, minlength=n + 1)[:n + 1]
        ends = np.bincount(i1, minlength=n + 1)[:n + 1]
        held = np.cumsum(starts - ends)[:n] > 0
        rows = np.flatnonzero(held)
        at = np.maximum(np.cumsum(held) - 1, 0)
    else:
        rows = np.arange(n)
        at = rows
    Jr = J[rows]
    wJ = w[rows][:, None, None] * Jr
    return at, wJ, np.swapaxes(wJ, 1, 2) @ Jr


def _mul(p: list, q: list) -> list:
    """Product of two polynomials given by power-basis coefficient lists."""
    out = [0.0] * (len(p) + len(q) - 1)
    for i, a in enumerate(p):
        for k, b in enumerate(q):
            out[i + k] = out[i + k] + a * b
    return out


def _reflect(c: list) -> list:
    """Coefficients of ``p(1 - x)`` from those of a cubic ``p(x)``."""
    c0, c1, c2, c3 = c
    return [c0 + c1 + c2 + c3, -c1 - 2 * c2 - 3 * c3, c2 + 3 * c3, -c3]


def _horner(c: list, x: np.ndarray, derivative: int = 0) -> np.ndarray:
    """A cubic's ``derivative``-th derivative at ``x`` (B, P); ``c`` four (B,) arrays."""
    for _ in range(derivative):
        c = [k * ck for k, ck in enumerate(c)][1:]
    out = c[-1][:, None] * np.ones_like(x)
    for ck in c[-2::-1]:
        out = out * x + ck[:, None]
    return out


def _new_splines(a: np.ndarray) -> list:
    """The three cubic B-splines a triple knot at ``τ = j + a`` adds (module docstring), on
    knots ``(-1, 0, a, a, a)``, ``(0, a, a, a, 1)`` and ``(a, a, a, 1, 2)`` in spacings from
    ``u_j``: per B-spline its two polynomial pieces as ``(lo, hi, coefficients)`` (``a`` (B,),
    coefficients four (B,) arrays in the power basis). Cox–de Boor worked out by hand; the
    third is the first's mirror image (``x → 1 - x``, ``a → 1 - a``)."""
    both = np.stack([a, 1 - a])  # the first B-spline's ``a`` and the mirrored third's
    one = np.ones_like(both)
    zero = np.zeros_like(both)

    def first(a):
        up = [one, one]  # x + 1
        down = [a, -one]  # a - x
        x = [zero, one]
        left = [c / (a + 1) ** 2 for c in _mul(_mul(up, up), up)]
        right = [p / ((a + 1) ** 2 * a) + q / ((a + 1) * a**2) + r / a**3 for p, q, r in zip(
            _mul(_mul(up, up), down), _mul(_mul(up, down), x), _mul(down, _mul(x, x)),
            strict=True)]
        return left, right

    left, right = first(both)  # both B-splines at once: row 0 for a, row 1 for b = 1 - a
    left1, right1 = [c[0] for c in left], [c[0] for c in right]
    left3, right3 = [c[1] for c in left], [c[1] for c in right]
    cube = both**-3
    one, zero = one[0], zero[0]
    middle_left = [zero, zero, zero, cube[0]]  # (x / a)³
    middle_right = _reflect([zero, zero, zero, cube[1]])  # ((1 - x) / b)³
    return [[(-one, zero, left1), (zero, a, right1)],
            [(zero, a, middle_left), (a, one, middle_right)],
            [(a, one, _reflect(right3)), (one, 2 * one, _reflect(left3))]]


def _gains(base: _Base, which: np.ndarray, tau: np.ndarray, centre: np.ndarray, prior
           ) -> np.ndarray:
    """Cost decrease (B,) of a triple knot at ``tau`` (B,) in window ``which`` (B,) of
    ``base``, whose uniform knots are ``centre + k·h`` (module docstring): ``trial_gains``
    of :func:`_trial_terms`."""
    from ._kernels import trial_gains

    return trial_gains(*_trial_terms(base, which, tau, centre, prior))


def _trial_terms(base: _Base, which: np.ndarray, tau: np.ndarray, centre: np.ndarray, prior
                 ) -> tuple:
    """The arguments of ``trial_gains`` for the trials of :func:`_gains`: the data terms
    ``Hyy``, ``Hxy``, the prior's ``pyy``, ``pxy``, the windows' inverses, each trial's
    window, the row and column of its 18 x 18 block, and ``g``.

    The per-trial terms are compiled passes (:mod:`pslog.estimation._kernels`:
    ``trial_splines``, ``gains_data``, ``trial_gather`` — the operations of
    :func:`_new_splines`, :func:`_horner` and the numpy forms, in order — and the prior's
    small products, ``trial_prior_terms``: k = 6 or 12, 3 columns, summed as OpenBLAS's
    kernels sum them, k in order with fused multiply-adds, tests/test_smooth_passes.py);
    the Schur complement ``S = H_yy - H_yxᵀ Σ H_xy`` and ``gᵀ S⁻¹ g`` are one compiled pass
    per trial (``trial_gains``: the products summed in loop order and Gaussian elimination
    with partial pivoting, where numpy's batched BLAS products and LAPACK solves took 2.4x
    the time). Their sums' order is not BLAS's and LAPACK's, and the gains amplify such
    changes (``S`` is a difference of nearly equal terms: the base explains most of what
    the break would): they moved by ~1e-9 relative, the breaks' instants and the points by
    far less than their noise (session 18, docs/methods.md)."""
    from ._kernels import gains_data, trial_gather, trial_prior_terms, trial_splines

    local, h = base.local, base.spacing
    K = local.K
    s = (tau - centre[which]) / h
    j = np.floor(s)
    a = s - j  # in spacings from u_j
    q0 = (j + K - 1).astype(np.int64)  # the six base control points over spans j-1..j+1
    both = np.stack([a, 1 - a])  # the first new B-spline's ``a`` and the mirrored third's
    lo, hi, coef, nodes, fn, fw, first, Nd = trial_splines(
        a, both**3, both**-3, s, j, K, h, h**2, h**3, _GAUSS, prior.q_accel, prior.q_jerk)
    # data: the window's detections on the three spans [j-1, j+2) the new B-splines live on:
    # Σ_w (f fᵀ) ⊗ M_w, Σ_w (old fᵀ) ⊗ M_w (old: the base's B-splines q0..q0+5) and Σ_w f uᵀ,
    # one compiled pass over each window's detections
    Hyy, Hxy, g = gains_data(base.s_sorted, base.first, base.N, base.M, base.u,
                             np.ascontiguousarray(which, dtype=np.int64), j, q0, lo, hi, coef)
    m = local.m

    # prior: four sub-spans [j-1, j], [j, τ], [τ, j+1], [j+1, j+2], each new B-spline one
    # polynomial piece on each of its two; the base's B-splines at the nodes are uniform
    # ones (closed form), but near the clamped ends
    clamped = (first < 3) | (first > 2 * K - 4)
    if np.any(clamped):
        f_c, N_c = basis(local.knots, nodes[clamped], 3)
        first[clamped] = f_c
        Nd[clamped] = np.where(_ACCEL[np.nonzero(clamped)[1]][:, None], N_c[:, 2] / h**2,
                               N_c[:, 3] / h**3)
    # the nodes' B-splines on the six base control points q0..q0+5 of the three spans
    Nd6, x0 = trial_gather(first, Nd, q0, base.x0.reshape(-1, 3), which * m + q0)
    # p'' or jerk less gravity p0 = Nd6 @ x0 - g (B, 12, 3), pyy = fw fnᵀ (B, 3, 3), pxy =
    # Nd6ᵀ fwᵀ (B, 6, 3), and g -= fw @ p0: the matmuls' sums, one compiled pass
    prior_terms = trial_prior_terms if prior_terms_compiled() else prior_terms_numpy
    _, pyy, pxy = prior_terms(Nd6, x0, np.ascontiguousarray(fw), np.ascontiguousarray(fn),
                              np.asarray(prior.gravity, dtype=np.float64), g)
    # ⊗ I₃ into the data terms, S = Hyy - H_yxᵀ Σ H_xy on the 18 x 18 diagonal block of each
    # window's inverse, symmetric, its diagonal loaded by 1e-12 of its largest entry, and
    # gᵀ S⁻¹ g: one compiled pass per trial (trial_gains)
    col0 = base.col0
    k = 3 * q0 - col0
    if np.any((k < 0) | (k > base.cov.shape[2] - 18)):
        raise AssertionError("trial instant outside the spans its base was solved for")
    return (Hyy, Hxy, pyy, pxy, base.cov, np.ascontiguousarray(which, np.int64), 3 * q0, k,
            g.reshape(len(tau), 9))


def prior_terms_numpy(Nd6: np.ndarray, x0: np.ndarray, fw: np.ndarray, fn: np.ndarray,
                      gravity: np.ndarray, g: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`pslog.estimation._kernels.trial_prior_terms` as numpy's matmuls (the form it
    repeats): ``p0 = Nd6 @ x0`` (B, 12, 3) less ``gravity`` at the 8 Gauss nodes, ``pyy =
    fw @ fnᵀ`` (B, 3, 3), ``pxy = Nd6ᵀ @ fwᵀ`` (B, 6, 3), and ``g -= fw @ p0`` in place."""
    p0 = Nd6 @ x0
    p0[:, :8] -= gravity
    pyy = fw @ np.swapaxes(fn, 1, 2)
    pxy = np.swapaxes(Nd6, 1, 2) @ np.swapaxes(fw, 1, 2)
    g -= fw @ p0
    return p0, pyy, pxy


@cache
def prior_terms_compiled() -> bool:
    """Whether ``trial_prior_terms`` gives :func:`prior_terms_numpy`'s bits here: it sums as
    OpenBLAS's kernels do on x86-64 with fused multiply-adds; another BLAS, CPU or numpy may
    sum otherwise (numpy's matmuls then). Probe terms of several batch sizes and
    magnitudes, checked once per process (~ms)."""
    from ._kernels import trial_prior_terms

    return _prior_terms_probe(trial_prior_terms)


def _prior_terms_probe(kernel) -> bool:
    """:func:`prior_terms_compiled`'s probe of a kernel with ``trial_prior_terms``' form."""
    rng = np.random.default_rng(23)
    gravity = np.array([0.0, 0.0, -9.81])
    for B in (1, 2, 3, 8, 64, 257):
        Nd6 = rng.normal(size=(B, 12, 6)) * 10.0 ** rng.integers(-3, 6, (B, 1, 1))
        x0, fw = rng.normal(size=(B, 6, 3)), rng.normal(size=(B, 3, 12))
        fn = rng.normal(size=(B, 3, 12)) * 1e4
        g0 = rng.normal(size=(B, 3, 3))
        want_g, got_g = g0.copy(), g0.copy()
        want = prior_terms_numpy(Nd6, x0, fw, fn, gravity, want_g)
        got = kernel(Nd6, x0, fw, fn, gravity, got_g)
        if not all(np.array_equal(a.view(np.int64), b.view(np.int64))
                   for a, b in zip((*want, want_g), (*got, got_g), strict=True)):
            return False
    return True


def scan(t: np.ndarray, J: np.ndarray, z: np.ndarray, w: np.ndarray, centers: np.ndarray,
         bounds: np.ndarray, limits: np.ndarray, spacing: float, half_width: float, prior,
         terms: tuple | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Best break instant in ``bounds`` and its cost gain, for every candidate at once.

    Parameters
    ----------
    t, J, z, w : detections sorted by time (see :class:`_Base`)
    centers : (C,) s, candidate instants; the window is ``center ± half_width``, cut at
        ``limits`` (C, 2) (neighbouring breaks, whose other side is not modelled here, and the
        piece's ends)
    bounds : (C, 2) s, the interval searched for ``τ``
    terms : :func:`detection_terms` of every detection of ``J``, ``w`` (made once by a
        caller that scans one linearisation several times), or None: made here for the
        detections the windows hold

    Returns
    -------
    tau : (C,) s; gain : (C,) cost without the break minus cost with it (σ² units)
    """
    tau, gain, _ = _scan(t, J, z, w, centers, bounds, limits, spacing, half_width, prior,
                         False, terms=terms)
    return tau, gain


def scan_near(t: np.ndarray, J: np.ndarray, z: np.ndarray, w: np.ndarray,
              centers: np.ndarray, bounds: np.ndarray, limits: np.ndarray, spacing: float,
              half_width: float, prior, narrow: bool = False, terms: tuple | None = None
              ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`scan` of breaks already located near ``centers``, ``bounds`` within ``h/4`` of
    them (a refinement): every trial instant is then at least ``h/4`` from the knots
    ``center + h/2 + k·h``, so one base serves (no centred one, no second solve per
    candidate), and the gains are not needed.

    ``narrow``: a grid of 3 trials over the bounds (``h/16`` either side, the caller's
    first search) and ``_NARROW_POLISH`` polishing stages, not ``_NEAR_GRID`` and
    ``_POLISH``.

    Returns
    -------
    tau : (C,) s, the best instant; edge : (C,) int, -1 / +1 where the first stage's best
        trial was ``bounds``' lower / upper end (the optimum may lie beyond it), else 0
    """
    # (the bounds were rounded from centre -/+ h/4: a few ulps of the centre allowed)
    if np.any(np.abs(bounds - centers[:, None])
              > spacing / 4 * (1 + 1e-9) + 4 * np.spacing(np.abs(centers))[:, None]):
        raise ValueError("scan_near: bounds further than h/4 from their centres")
    stages = (3, _NARROW_POLISH) if narrow else (_NEAR_GRID, _POLISH)
    tau, _, edge = _scan(t, J, z, w, centers, bounds, limits, spacing, half_width, prior,
                         True, stages, terms)
    return tau, edge


def gain_at(t: np.ndarray, J: np.ndarray, z: np.ndarray, w: np.ndarray,
            centers: np.ndarray, bounds: np.ndarray, limits: np.ndarray, spacing: float,
            half_width: float, prior, terms: tuple | None = None
            ) -> tuple[np.ndarray, np.ndarray]:
    """The gain of a break at each of ``centers`` itself (one trial on :func:`scan_near`'s
    base, no search; ``bounds`` must be ``[centre, centre]``): what a break already located
    there saves on the problem linearised at a fit (``smooth``'s confirmation of its
    refined breaks at the fit under the real prior,
    :func:`pslog.estimation.trajectory._confirmed_breaks`).

    Returns
    -------
    tau : (C,) s, ``centers``; gain : (C,) cost without the break minus cost with it (σ²
    units)
    """
    if np.any(bounds != centers[:, None]):
        raise ValueError("gain_at: bounds must be [centre, centre]")
    tau, gain, _ = _scan(t, J, z, w, centers, bounds, limits, spacing, half_width, prior,
                         True, (1, 0), terms)
    return tau, gain


def _scan(t: np.ndarray, J: np.ndarray, z: np.ndarray, w: np.ndarray, centers: np.ndarray,
          bounds: np.ndarray, limits: np.ndarray, spacing: float, half_width: float, prior,
          near: bool, stages: tuple[int, int] = (_GRID, _POLISH), terms: tuple | None = None
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`scan` (``near`` False) and :func:`scan_near` (True): tau, gain, edge;
    ``stages``: the grid's trials and the polishing stages; ``terms``: :func:`scan`'s."""
    C = len(centers)
    if C == 0:
        return np.zeros(0), np.zeros(0), np.zeros(0, np.int64)
    lo = np.maximum(centers - half_width, limits[:, 0])
    hi = np.minimum(centers + half_width, limits[:, 1])
    i0 = np.searchsorted(t, lo, side="left")
    i1 = np.searchsorted(t, hi, side="right")
    # the window length, the knot pattern and the spans solved for are the whole scan's:
    # every block of candidates below then computes exactly what one batch of all did
    Wmax = max(int(np.max(i1 - i0)), 1)
    # knots reach the window and two spans beyond any trial instant
    reach = max(half_width, float(np.max(np.abs(bounds - centers[:, None]))) + 2.5 * spacing)
    K = int(np.ceil(reach / spacing)) + 1
    local = _local(K, spacing, prior, 1)
    # the spans a trial instant may fall in, on either base (the shifted one h/2 later)
    rel = (bounds - centers[:, None]) / spacing
    spans = (int(np.floor(np.min(rel))) - 1, int(np.floor(np.max(rel))))

    if terms is None:
        terms = detection_terms(J, w, i0, i1)

    def block(c0: int, c1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The scan of candidates c0..c1-1 (each candidate's result depends on its own
        window only)."""
        return _scan_block(t, J, z, w, centers[c0:c1], bounds[c0:c1], i0[c0:c1],
                           i1[c0:c1], Wmax, local, spacing, spans, prior, terms, near,
                           stages)

    jobs = [(c0, min(c0 + _BLOCK, C)) for c0 in range(0, C, _BLOCK)]
    threads = scan_threads(len(jobs))
    if threads > 1:
        # the kernels release the GIL and the large numpy operations do too; each block's
        # result lands in its own place, so the output does not depend on the thread count
        parts = on_threads(block, jobs, threads)
    else:
        parts = [block(c0, c1) for c0, c1 in jobs]
    return tuple(np.concatenate([part[i] for part in parts])  # type: ignore[return-value]
                 for i in range(3))


def vertex(gm: np.ndarray, g0: np.ndarray, gp: np.ndarray) -> np.ndarray:
    """Where the parabola through gains ``(-1, gm), (0, g0), (1, gp)`` peaks, in units of
    their spacing from the middle one, within [-1, 1]; where it opens upward (or is flat)
    the better end (0 when they are equal)."""
    with np.errstate(invalid="ignore"):  # (-inf gains: NaN, handled below)
        curv = gm + gp - 2 * g0  # negative: a maximum
        cap = curv < 0
        shift = np.where(cap, 0.5 * (gm - gp) / np.where(cap, curv, -1.0), np.sign(gp - gm))
    # a gain that is not finite (-inf: no break fits there) leaves no parabola: stay
    return np.clip(np.where(np.isfinite(shift), shift, 0.0), -1.0, 1.0)


def _scan_block(t: np.ndarray, J: np.ndarray, z: np.ndarray, w: np.ndarray,
                centers: np.ndarray, bounds: np.ndarray, i0: np.ndarray, i1: np.ndarray,
                Wmax: int, local: _Local, spacing: float, spans: tuple[int, int], prior,
                terms=None, near: bool = False, stages: tuple[int, int] = (_GRID, _POLISH)
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_scan` of a block of candidates (C,), their windows ``t[i0:i1]`` padded to
    ``Wmax`` detections, on the scan's knot pattern ``local`` and ``spans``.

    The search: a grid of ``_GRID`` trial instants over ``bounds`` (``_NEAR_GRID`` with
    ``near``), then ``_POLISH`` stages of three trials ``v - d, v, v + d`` each, ``v`` the
    previous stage's parabola vertex and ``d`` a quarter of the previous step, then one
    trial at the last vertex; the best trial of all wins."""
    C = len(centers)
    index = i0[:, None] + np.arange(Wmax)
    valid = index < i1[:, None]
    index = np.minimum(index, len(t) - 1)
    rows = np.arange(C)
    if near:
        # one base, knots at the centre + h/2 + k·h: every trial instant (within h/4 of the
        # centre) is at least h/4 from them
        both = centers + spacing / 2
        base = _Base(local, t, J, z, w, index, valid, both, spacing, spans, terms)
    else:
        # two bases, knots at the centre + k·h and shifted by h/2 (windows C..2C-1): a trial
        # instant is tested on the one whose knots are at least h/4 away from it
        both = np.r_[centers, centers + spacing / 2]
        base = _Base(local, t, J, z, w, np.r_[index, index], np.r_[valid, valid], both,
                     spacing, spans, terms)

    def gains(which, tau):
        """Cost of the centred base minus the least cost with a break at ``tau`` (with
        ``near``: of the shifted base)."""
        if near:
            on = which
        else:
            frac = (tau - centers[which]) / spacing
            frac -= np.floor(frac)
            on = which + C * ((frac < 0.25) | (frac > 0.75))
        out = np.empty(len(tau))
        for s in range(0, len(tau), _BATCH):
            sl = slice(s, s + _BATCH)
            out[sl] = _gains(base, on[sl], tau[sl], both, prior)
            if not near:
                out[sl] += base.cost[which[sl]] - base.cost[on[sl]]
        # a failed solve's NaN is no gain (argmax and the comparisons below would take it)
        out[np.isnan(out)] = -np.inf
        return out

    a, b = bounds[:, 0], bounds[:, 1]
    P, polish = stages
    if P == 1:  # one trial, at the bounds' lower end (:func:`gain_at`: no search)
        return a.copy(), gains(rows, a), np.zeros(C, np.int64)
    grid = a[:, None] + (b - a)[:, None] * np.linspace(0, 1, P)[None, :]
    gain = gains(np.repeat(rows, P), grid.ravel()).reshape(C, P)
    k = np.argmax(gain, axis=1)
    best, best_tau = gain[rows, k], grid[rows, k]
    edge = np.where(k == 0, -1, np.where(k == P - 1, 1, 0))
    step = (b - a) / (P - 1)
    # a parabola through the best grid point and its neighbours (at an end: that end)
    km, kp = np.maximum(k - 1, 0), np.minimum(k + 1, P - 1)
    shift = np.where(edge == 0, vertex(gain[rows, km], best, gain[rows, kp]), 0.0)
    v = best_tau + shift * step
    for _ in range(polish):
        step = step / 4
        # three trials around v, inside the bounds
        v = np.clip(v, np.minimum(a + step, (a + b) / 2), np.maximum(b - step, (a + b) / 2))
        trial = v[:, None] + step[:, None] * np.array([-1.0, 0.0, 1.0])
        trial = np.clip(trial, a[:, None], b[:, None])
        g3 = gains(np.repeat(rows, 3), trial.ravel()).reshape(C, 3)
        k = np.argmax(g3, axis=1)
        better = g3[rows, k] > best
        best = np.where(better, g3[rows, k], best)
        best_tau = np.where(better, trial[rows, k], best_tau)
        v = np.clip(v + vertex(g3[:, 0], g3[:, 1], g3[:, 2]) * step, a, b)
    final = gains(rows, v)
    use = final > best
    return np.where(use, v, best_tau), np.where(use, final, best), edge
