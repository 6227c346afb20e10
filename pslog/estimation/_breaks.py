"""Batched search for the instant of a velocity jump (a bounce or a kick).

For a candidate near ``t_c``, the reprojection problem linearised at the current fit
(``J_i X ≈ z_i`` per detection, weights ``w_i / σ²``) is solved on a local window under the
motion prior, once with a spline that is C² everywhere and once for each trial instant ``τ``
with a triple knot (C⁰) at ``τ``. The local knots are ``τ + k·h`` for integers ``k`` — the
trial instant is always a knot and the local problem has the same structure for every ``τ``
(the prior's normal matrix is shift invariant and computed once) — so every (candidate, τ) pair
is one small dense solve, and all of them run as one batched call. ``τ`` is found by three
nested grid scans and a parabola through the best three costs; the gain of the break is the
cost without it minus the cost with it (a likelihood ratio in units of σ²).
"""

from __future__ import annotations

import numpy as np

from .bspline import basis, clamped_knots, n_control

_GRID = 7  # trial instants per scan
_STAGES = 3
_BATCH = 400  # (candidate, τ) pairs per batched solve: bounds memory


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
        ab, rhs, const = _prior_normal([spacing * self.knots], np.zeros(1, np.int64), self.m,
                                       prior)
        n = 3 * self.m
        P = np.zeros((n, n))
        for d in range(12):
            i = np.arange(n - d)
            P[i, i + d] = ab[11 - d, d:]
            P[i + d, i] = ab[11 - d, d:]
        self.P, self.rhs, self.const = P, rhs, const


def local_costs(local: _Local, t: np.ndarray, J: np.ndarray, z: np.ndarray, w: np.ndarray,
                index: np.ndarray, valid: np.ndarray, tau: np.ndarray, spacing: float
                ) -> np.ndarray:
    """Minimum of the local linearised cost for each window and trial instant.

    Parameters
    ----------
    local : _Local
    t, J, z, w : (n,), (n, 2, 3), (n, 2), (n,) the piece's detection times (s), Jacobians,
        linearised targets and weights (already divided by σ²)
    index : (B, W) int, detections of each window; valid : (B, W) bool (padding False)
    tau : (B,) float, the trial instants (the middle knot)

    Returns
    -------
    cost : (B,) float
    """
    out = np.empty(len(tau))
    for lo in range(0, len(tau), _BATCH):
        sl = slice(lo, lo + _BATCH)
        out[sl] = _costs(local, t, J, z, w, index[sl], valid[sl], tau[sl], spacing)
    return out


def _costs(local, t, J, z, w, index, valid, tau, spacing):
    B, W = index.shape
    s = (t[index] - tau[:, None]) / spacing
    inside = valid & (np.abs(s) < local.K - 1e-9)
    s = np.where(inside, s, 0.0)
    first, N = basis(local.knots, s.ravel(), 0)
    first = first.reshape(B, W)
    N = N[:, 0].reshape(B, W, 4)
    wi = np.where(inside, w[index], 0.0)
    n = 3 * local.m
    # dense design (B, 2W, n): row (i, axis) has N_a ∂uv_axis/∂X_d at column 3(first+a)+d
    D = np.zeros((B, W, 2, n))
    Ji = J[index]  # (B, W, 2, 3)
    cols = 3 * first[..., None] + np.arange(12)  # (B, W, 12)
    vals = (N[:, :, None, :, None] * Ji[:, :, :, None, :]).reshape(B, W, 2, 12)
    b_idx = np.arange(B)[:, None, None, None]
    w_idx = np.arange(W)[None, :, None, None]
    a_idx = np.arange(2)[None, None, :, None]
    D[b_idx, w_idx, a_idx, cols[:, :, None, :]] = vals
    D = D.reshape(B, 2 * W, n)
    zw = z[index].reshape(B, 2 * W)
    ww = np.repeat(wi, 2, axis=1)
    Dw = D * ww[..., None]
    DwT = np.swapaxes(Dw, 1, 2)
    H = DwT @ D + local.P  # batched BLAS
    rhs = (DwT @ zw[..., None])[..., 0] + local.rhs
    H[:, np.arange(n), np.arange(n)] *= 1 + 1e-12  # keeps a degenerate window solvable
    x = np.linalg.solve(H, rhs[..., None])[..., 0]
    return np.sum(ww * zw * zw, axis=1) + local.const - np.einsum("bk,bk->b", rhs, x)


def scan(t: np.ndarray, J: np.ndarray, z: np.ndarray, w: np.ndarray, centers: np.ndarray,
         bounds: np.ndarray, limits: np.ndarray, spacing: float, half_width: float, prior
         ) -> tuple[np.ndarray, np.ndarray]:
    """Best break instant in ``bounds`` and its cost gain, for every candidate at once.

    Parameters
    ----------
    t, J, z, w : one piece's detections (see :func:`local_costs`)
    centers : (C,) s, candidate instants; the window is ``center ± half_width``, cut at
        ``limits`` (C, 2) (neighbouring breaks, whose other side is not modelled here)
    bounds : (C, 2) s, the interval searched for ``τ``

    Returns
    -------
    tau : (C,) s; gain : (C,) cost without the break minus cost with it (σ² units)
    """
    C = len(centers)
    if C == 0:
        return np.zeros(0), np.zeros(0)
    lo = np.maximum(centers - half_width, limits[:, 0])
    hi = np.minimum(centers + half_width, limits[:, 1])
    i0 = np.searchsorted(t, lo, side="left")
    i1 = np.searchsorted(t, hi, side="right")
    Wmax = int(np.max(i1 - i0))
    index = i0[:, None] + np.arange(Wmax)
    valid = index < i1[:, None]
    index = np.minimum(index, len(t) - 1)
    reach = half_width + np.max(bounds[:, 1] - bounds[:, 0]) + spacing
    K = int(np.ceil(reach / spacing)) + 1
    plain = _Local(K, spacing, prior, 1)
    broken = _Local(K, spacing, prior, 3)
    base = local_costs(plain, t, J, z, w, index, valid, centers, spacing)
    a, b = bounds[:, 0].copy(), bounds[:, 1].copy()
    best_tau = (a + b) / 2
    best = np.full(C, np.inf)
    for _ in range(_STAGES):
        grid = a[:, None] + (b - a)[:, None] * np.linspace(0, 1, _GRID)[None, :]
        costs = local_costs(broken, t, J, z, w, np.repeat(index, _GRID, axis=0),
                            np.repeat(valid, _GRID, axis=0), grid.ravel(),
                            spacing).reshape(C, _GRID)
        k = np.argmin(costs, axis=1)
        rows = np.arange(C)
        better = costs[rows, k] < best
        best = np.where(better, costs[rows, k], best)
        best_tau = np.where(better, grid[rows, k], best_tau)
        step = (b - a) / (_GRID - 1)
        # a parabola through the best grid point and its neighbours
        km, kp = np.maximum(k - 1, 0), np.minimum(k + 1, _GRID - 1)
        c0, cm, cp = costs[rows, k], costs[rows, km], costs[rows, kp]
        curv = cm + cp - 2 * c0
        inner = (k > 0) & (k < _GRID - 1) & (curv > 0)
        shift = np.where(inner, 0.5 * (cm - cp) / np.where(inner, curv, 1.0), 0.0)
        centre = grid[rows, k] + shift * step
        a = np.maximum(centre - step, bounds[:, 0])
        b = np.minimum(centre + step, bounds[:, 1])
    final = local_costs(broken, t, J, z, w, index, valid, (a + b) / 2, spacing)
    use = final < best
    best_tau = np.where(use, (a + b) / 2, best_tau)
    best = np.where(use, final, best)
    return best_tau, base - best
