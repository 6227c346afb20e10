"""Type A's innovation test: a point whose prediction the newest detection contradicts.

Type A's output ``P'_t`` (eqs. (2)-(4) of the paper) takes its depth along the newest
viewing ray from the linear prediction ``P̂_t = P_{t-1} + ρ (P_{t-1} - P_{t-2})``,
``ρ = δ_pred / δ_prev``. Across a kick or a bounce (a change of motion between the past
points and the newest detection), and all the more across the long gaps a blind camera
leaves, the prediction is wrong, and eq. (4) puts the point at the wrong depth: the
newest camera cannot see a depth error, but it does see the prediction's error across
its ray. The *innovation* ``r`` (pixels, in the recorded image) is the distance between the
newest detection and the projection of ``P̂_t``; under the model (ballistic motion between
the three instants, Gaussian detection noise ``σ`` per image axis) it is

- noise: each past point, triangulated from detections, projects into the newest camera
  with an error of about ``σ`` per axis; ``P̂_t`` combines them with weights ``1 + ρ`` and
  ``ρ``, and the newest detection adds its own, so ``σ_r = σ √(1 + (1 + ρ)² + ρ²)`` per axis;
- model: eq. (2) extrapolates linearly; under a constant acceleration ``a`` its error is
  exactly ``½ a δ_pred (δ_pred + δ_prev)`` (the remainder of linear interpolation through
  ``t-2`` and ``t-1`` evaluated at ``t``), at most ``½ g δ_pred (δ_pred + δ_prev)`` for a
  ball in flight; a motion across the ray at distance ``D``, ``θ`` off the optical axis,
  moves the image by ``f / (D cos² θ)`` pixels per metre radially and ``f / (D cos θ)``
  tangentially, so the bound takes ``f D / Z²`` (``Z = D cos θ``, depth along the axis).

``σ`` is at least the stated noise and at least the noise the session's earlier innovations
imply (:class:`NoiseEstimate`): a stated noise below the detector's real one would refuse
good points in numbers.

The point is refused when ``r > k σ_r + e_model`` with ``k = 5``: for a Gaussian 2D error
``P(|r| > k σ_r) = exp(-k² / 2) ≈ 4e-6``, so under the model (and the stated noise) a valid
point is essentially never refused; the test fires when the model failed — the motion
changed inside the prediction's interval — which is what it is for. It is the innovation
test a Kalman filter applies to each measurement (Bar-Shalom, Li and Kirubarajan, *Estimation
with Applications to Tracking and Navigation*, 2001, ch. 5.4), applied to eq. (2)'s
prediction. docs/methods.md, "Type A's prediction test", has the figures.

Below the refusal, a second level (session 32): a point whose innovation across the newest
ray, gravity's part taken out, exceeds 3 standard deviations is not refused but waits for the
next camera's confirmation (:data:`pslog.fusion.confirm.WAIT_SIGMAS`,
:func:`pslog.fusion.confirm.innovation_waits`; docs/methods.md, "A point with a large
innovation waits").
"""

from __future__ import annotations

import functools
import math

import numpy as np

from ..motion import G
from ..records import NS

#: Refuse a prediction whose innovation exceeds this many standard deviations (plus the
#: model bound): a Gaussian 2D innovation does with probability exp(-K²/2) ~ 4e-6.
INNOVATION_SIGMAS = 5.0
#: The detection noise assumed when the caller gives none (FusionOptions' default), and the
#: tests' least σ until NoiseEstimate holds NOISE_EVERY innovations.
DEFAULT_NOISE_PX = 0.5
#: The probability, under the model and the right noise, that a test of this module's level
#: refuses a valid point: a 2D Gaussian innovation beyond INNOVATION_SIGMAS σ, exp(-25/2).
#: The N-view residual test (:func:`pslog.fusion.stereo.residual_refused`) takes its χ²
#: threshold at the same level.
REFUSAL_PROBABILITY = math.exp(-INNOVATION_SIGMAS ** 2 / 2.0)


def chi2_survival(x: float, dof: int) -> float:
    """``P(χ²_dof > x)`` of an integer ``dof >= 1``, in closed form: for an even ``dof = 2m``
    ``e^{-x/2} Σ_{j<m} (x/2)^j / j!``; for an odd ``dof = 2m + 1``
    ``erfc(√(x/2)) + √(2x/π) e^{-x/2} Σ_{j=1..m} x^{j-1} / (1·3···(2j-1))``."""
    if x <= 0.0:
        return 1.0
    if dof % 2 == 0:
        term, total = 1.0, 1.0
        for j in range(1, dof // 2):
            term *= 0.5 * x / j
            total += term
        return math.exp(-0.5 * x) * total
    term, total = 1.0, 0.0
    for j in range(1, (dof - 1) // 2 + 1):
        total += term
        term *= x / (2 * j + 1)
    return math.erfc(math.sqrt(0.5 * x)) + math.sqrt(2.0 * x / math.pi) * math.exp(
        -0.5 * x) * total


@functools.lru_cache(maxsize=64)
def chi2_threshold(dof: int, p: float = REFUSAL_PROBABILITY) -> float:
    """The ``x`` with ``P(χ²_dof > x) = p`` (bisection on :func:`chi2_survival`, to 1e-12
    relative): at :data:`REFUSAL_PROBABILITY` and 2 degrees of freedom, ``25`` (type A's 5σ)."""
    lo, hi = 0.0, 1.0
    while chi2_survival(hi, dof) > p:
        lo, hi = hi, 2.0 * hi
    while hi - lo > 1e-12 * hi:
        mid = 0.5 * (lo + hi)
        if chi2_survival(mid, dof) > p:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


#: Median of the norm of a 2D Gaussian of σ per axis, in σ: Rayleigh's median √(2 ln 2).
RAYLEIGH_MEDIAN = float(np.sqrt(2.0 * np.log(2.0)))
#: The noise estimate: the median of the last NOISE_WINDOW innovations, renewed every
#: NOISE_EVERY innovations (vectorised in a batch run, the same values in a stream); until
#: NOISE_EVERY innovations exist, the tests' σ is at least DEFAULT_NOISE_PX.
NOISE_WINDOW = 256
NOISE_EVERY = 32  # (a power of two: NoiseEstimate.sigmas clears its low bits)
#: the buffer NoiseEstimate keeps its last NOISE_WINDOW + NOISE_EVERY innovations in (the
#: one-point path appends in place; moved to the front when full)
_TAIL_BUFFER = 2 * (NOISE_WINDOW + NOISE_EVERY)
assert NOISE_EVERY & (NOISE_EVERY - 1) == 0, "NoiseEstimate.sigmas needs a power of two"
#: Windows selected at once by :meth:`NoiseEstimate.sigmas` (64 KB blocks).
_MEDIAN_ROWS = 32


def innovation_factors(events: np.ndarray, j1: np.ndarray, j2: np.ndarray,
                       time_ns: np.ndarray) -> np.ndarray:
    """``√(1 + (1 + ρ)² + ρ²)``: the innovation's noise in units of the detection noise σ
    (module docstring), (k,) float, for the rows ``events`` and past points ``j1, j2``."""
    return _factors((time_ns[events] - time_ns[j1]) / NS, (time_ns[j1] - time_ns[j2]) / NS)


def _factors(delta_pred: np.ndarray, delta_prev: np.ndarray) -> np.ndarray:
    """:func:`innovation_factors` of the intervals ``t - t1`` and ``t1 - t2``, seconds."""
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = delta_pred / delta_prev
        return np.sqrt(1.0 + (1.0 + rho) ** 2 + rho ** 2)


class NoiseEstimate:
    """The detection noise the session's own eq. (2) innovations imply, causally.

    The tests of this module assume a detection noise ``σ``; the one the user states
    (``noise_px``) is often too small (a detector's real noise is rarely measured), and a
    too small ``σ`` refuses good points in numbers. Each made point's innovation ``r``
    divided by its factor ``√(1 + (1 + ρ)² + ρ²)`` is, under the model, the norm of a 2D
    Gaussian of ``σ`` per axis (plus the small extrapolation error, which can only raise the
    estimate), whose median is ``σ √(2 ln 2)`` (Rayleigh). A point's tests use

        ``σ_t = max(noise_px, median(r_i / factor_i) / √(2 ln 2))``

    the median over the last ``NOISE_WINDOW`` (256) innovations before the latest multiple
    of ``NOISE_EVERY`` (32) innovations made before the point (the middle element: a
    selection, no arithmetic); at least 0.5 px before the first 32. A median is robust: the
    kicks and bounces the tests are there for are a few percent of the points. The estimate
    takes every made, valid point's innovation, refused or not (it never depends on the
    tests' decisions), in row order, so :class:`~pslog.fusion.pseudo.TypeAStream` (one
    instance across its pushes) gives each point the batch run's ``σ``, bit for bit.
    """

    def __init__(self) -> None:
        self._count = 0  # innovations so far
        # the last NOISE_WINDOW + NOISE_EVERY of them (every window still to be needed):
        # _buffer[_lo:_hi] (_tail), appended to in place by the one-point path
        self._buffer = np.zeros(_TAIL_BUFFER)
        self._lo = self._hi = 0
        # (checkpoint, median of its window), made once by the one-point path
        self._median: tuple[int, float] | None = None

    @property
    def _tail(self) -> np.ndarray:
        """The last NOISE_WINDOW + NOISE_EVERY innovations (all of them before), (<= 288,)."""
        return self._buffer[self._lo:self._hi]

    @_tail.setter
    def _tail(self, values: np.ndarray) -> None:
        k = len(values)
        self._buffer[:k] = values
        self._lo, self._hi = 0, k

    @property
    def count(self) -> int:
        """How many innovations the estimate has taken."""
        return self._count

    @property
    def tail(self) -> np.ndarray:
        """The last ``NOISE_WINDOW + NOISE_EVERY`` innovations taken (all of them before),
        oldest first: every window a later point can still need (a view, not to be
        written)."""
        return self._tail

    def advance(self, values: np.ndarray, count: int) -> None:
        """The estimate after a batch whose innovations were appended elsewhere (type A's
        kernel, which takes the tests' σ in its loop: the same selections as
        :meth:`sigmas`): ``values`` holds :attr:`tail` then the new innovations, ``count``
        the innovations taken in all (:attr:`count` and the new ones)."""
        end = len(self._tail) + count - self._count
        self._tail = values[max(0, end - (NOISE_WINDOW + NOISE_EVERY)):end]
        self._count = count

    def sigmas(self, normalised: np.ndarray, noise_px: float | None) -> np.ndarray:
        """Each point's ``σ_t`` (pixels, (k,) float), then its innovation taken.

        Parameters
        ----------
        normalised : (k,) float, ``r / factor`` of the points in row order, pixels (NaN: a
            point not made, invalid, or not projectable; not taken)
        noise_px : float or None, the stated noise per image axis, pixels (None: 0.5)
        """
        floor = DEFAULT_NOISE_PX if noise_px is None else float(noise_px)
        normalised = np.asarray(normalised, dtype=np.float64)
        if normalised.shape == (1,):  # one point (a stream's push): the same value, scalar
            return self._one(float(normalised[0]), floor)
        valid = ~np.isnan(normalised)
        values = normalised[valid]
        # innovations taken before each point, and the checkpoint (a multiple of EVERY) it uses
        before = self._count + np.cumsum(valid) - valid
        # before // NOISE_EVERY * NOISE_EVERY: the low bits cleared (a power of two; before
        # >= 0), without numpy's integer division, the dearest operation of this method
        checkpoint = before & -NOISE_EVERY
        # the innovations kept and the new ones: global index g at combined[g - offset]
        combined = np.concatenate([self._tail, values])
        offset = self._count - len(self._tail)
        out = np.full(len(normalised), max(floor, DEFAULT_NOISE_PX))
        first, last = (int(checkpoint[0]), int(checkpoint[-1])) if len(normalised) else (0, 0)
        marks = np.arange(max(first, NOISE_EVERY), last + 1, NOISE_EVERY, dtype=np.int64)
        if len(marks):
            medians = np.empty(len(marks))
            full = marks >= NOISE_WINDOW  # a whole window: all at once
            for i in np.flatnonzero(~full).tolist():  # (the session's first few only)
                window = combined[:int(marks[i]) - offset]
                medians[i] = np.partition(window, len(window) // 2)[len(window) // 2]
            if np.any(full):
                starts = marks[full] - NOISE_WINDOW - offset
                windows = np.lib.stride_tricks.sliding_window_view(combined, NOISE_WINDOW)
                half = NOISE_WINDOW // 2
                # the windows gathered and partitioned in place, _MEDIAN_ROWS at a time (a
                # session's windows at once were two fresh copies of them all, 1.4 MB for two
                # minutes, whose page faults cost more than the selection; a small block
                # reuses the allocator's memory); the same selections, row by row
                at = np.flatnonzero(full)
                for lo in range(0, len(starts), _MEDIAN_ROWS):
                    rows = windows[starts[lo:lo + _MEDIAN_ROWS]]
                    rows.partition(half, axis=1)
                    medians[at[lo:lo + _MEDIAN_ROWS]] = rows[:, half]
            use = checkpoint >= NOISE_EVERY
            implied = medians[(checkpoint[use] - marks[0]) // NOISE_EVERY] / RAYLEIGH_MEDIAN
            out[use] = np.maximum(floor, implied)
        self._count += len(values)
        self._tail = combined[-(NOISE_WINDOW + NOISE_EVERY):]
        return out

    def _one(self, value: float, floor: float) -> np.ndarray:
        """:meth:`sigmas` of one point (``value``: its ``r / factor``, NaN: not taken), as a
        (1,) array: the median of its checkpoint, a selection, is made once per checkpoint
        (every NOISE_EVERY innovations) instead of at every point."""
        sigma = self.next_sigma(floor)
        self.take(value)
        return np.array([sigma])

    def next_sigma(self, floor: float) -> float:
        """The σ (pixels) :meth:`sigmas` gives the next point, whatever its value (its
        checkpoint's, made from the innovations before it), ``floor``: the stated noise
        (None's 0.5 given as such)."""
        checkpoint = self._count // NOISE_EVERY * NOISE_EVERY
        sigma = max(floor, DEFAULT_NOISE_PX)
        if checkpoint >= NOISE_EVERY:
            if self._median is None or self._median[0] != checkpoint:
                # the last NOISE_WINDOW innovations before the checkpoint (all of them before
                # NOISE_WINDOW), all in the tail: it keeps NOISE_EVERY more than a window
                offset = self._count - len(self._tail)
                window = self._tail[max(0, checkpoint - NOISE_WINDOW) - offset:
                                    checkpoint - offset]
                half = len(window) // 2
                self._median = (checkpoint, float(np.partition(window, half)[half]))
            sigma = max(floor, self._median[1] / RAYLEIGH_MEDIAN)
        return sigma

    def take(self, value: float) -> None:
        """One point's innovation ``r / factor`` taken after its σ (NaN: none taken)."""
        if value == value:  # (not NaN: taken)
            self._count += 1
            hi = self._hi
            if hi == _TAIL_BUFFER:  # (the kept ones to the front, once in a while)
                keep = NOISE_WINDOW + NOISE_EVERY - 1
                self._buffer[:keep] = self._buffer[hi - keep:hi].copy()
                self._lo, hi = 0, keep
            self._buffer[hi] = value
            self._hi = hi = hi + 1
            if hi - self._lo > NOISE_WINDOW + NOISE_EVERY:
                self._lo = hi - (NOISE_WINDOW + NOISE_EVERY)


def failed_predictions(prep, events: np.ndarray, j1: np.ndarray, j2: np.ndarray,
                       predicted: np.ndarray, innovation_px: np.ndarray,
                       noise_px: float | np.ndarray | None) -> np.ndarray:
    """Which type A points the newest detection contradicts (module docstring).

    Parameters
    ----------
    prep : pslog.fusion._prepare.Prepared, the session's observations
    events, j1, j2 : (k,) int, rows of the newest detection and of ``P_{t-1}``, ``P_{t-2}``
    predicted : (k, 3) float, eq. (2)'s ``P̂_t``, world metres
    innovation_px : (k,) float, distance between the newest detection and the projection
        of ``P̂_t``, recorded-image pixels (NaN: not projectable; never refused here, the
        validity flags judge it)
    noise_px : float, (k,) float or None, the detections' noise per image axis, pixels
        (None: 0.5; an array: each point's, :meth:`NoiseEstimate.sigmas`)

    Returns
    -------
    (k,) bool, True where the innovation exceeds ``k σ_r + e_model``
    """
    time_ns = prep.obs.time_ns
    return contradicted(prep, events, (time_ns[events] - time_ns[j1]) / NS,
                        (time_ns[j1] - time_ns[j2]) / NS, predicted, innovation_px, noise_px)


def contradicted(prep, events: np.ndarray, delta_pred: np.ndarray, delta_prev: np.ndarray,
                 predicted: np.ndarray, innovation_px: np.ndarray,
                 noise_px: float | np.ndarray | None) -> np.ndarray:
    """:func:`failed_predictions`' test with the prediction's intervals given, seconds:
    ``delta_pred`` from the later past point to the newest detection, ``delta_prev`` between
    the past points (``typeB`` and ``linear`` predict from stereo points, not detections)."""
    cam = prep.obs.camera[events]
    lens = prep.lens_rows
    focal = np.maximum(lens[:, 0], lens[:, 1])[cam]
    axis = lens[cam, 4:7]  # optical axes in the world
    sigma = DEFAULT_NOISE_PX if noise_px is None else np.asarray(noise_px, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        sigma_r = sigma * _factors(delta_pred, delta_prev)
        offset = predicted - prep.ray_origin[events]
        depth = np.linalg.norm(offset, axis=1)
        z = np.sum(offset * axis, axis=1)  # depth along the optical axis, D cos θ
        # a motion e across the ray at distance D, θ off the optical axis, moves the image by
        # f e / (D cos² θ) radially (u = f tan θ) and f e / (D cos θ) tangentially: the larger
        # is f D / Z² pixels per metre (f / D on the axis only)
        model_px = 0.5 * G * delta_pred * (delta_pred + delta_prev) * focal * depth / (z * z)
        return innovation_px > INNOVATION_SIGMAS * sigma_r + model_px


def failed_counts(failed: np.ndarray, kinked: np.ndarray | None = None) -> dict[str, int]:
    """``Track.dropped``'s counts of the points :func:`failed_predictions` (and
    :func:`kinked_points`) refused."""
    n = int(np.count_nonzero(failed))
    m = 0 if kinked is None else int(np.count_nonzero(kinked))
    return {**({"prediction_failed": n} if n else {}), **({"kink": m} if m else {})}


#: Refuse a point whose partner's 2D track bends by more than this many standard deviations
#: (plus the model bound) inside eq. (1)'s interval: the same probability as the prediction's.
KINK_SIGMAS = 5.0


def previous_next_rows(prep) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_previous_next` of ``prep``'s observations, made once per Prepared (the kink
    test and the long-gap confirmation read it; not to be written)."""
    cache = prep.__dict__.get("_previous_next")
    if cache is None:
        cache = prep.__dict__["_previous_next"] = _previous_next(prep.obs.camera)
    return cache


def _previous_next(camera: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each row's previous and next row of the same camera (-1: none), (n,) int64 each."""
    from . import _prepare_kernel  # (numba: imported at the first use)

    n = len(camera)
    before, after = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
    # (one compiled pass each way: a stable argsort by camera did the same, 10x slower)
    _prepare_kernel.previous_next(np.ascontiguousarray(camera, dtype=np.int64),
                                  int(camera.max()) + 1 if n else 0, before, after)
    return before, after


def kinked_points(prep, events: np.ndarray, past: tuple, noise_px: float | np.ndarray | None,
                  max_gap_ns: int) -> np.ndarray:
    """Which type A points rest on an interval in which some camera saw the motion change.

    Eq. (1) interpolates a partner camera's 2D track linearly between its detections
    ``prev`` and ``next``; a kick or a bounce between them puts the interpolated point off
    the ball's image *along the epipolar line*, where the snap cannot see it, and the point
    at the wrong depth. In a camera's own 2D track a kick shows as a jump of the pixel
    velocity: for three consecutive detections ``a, b, c`` of one camera (undistorted pixels
    ``u``, capture intervals ``δ1 = t_b - t_a``, ``δ2 = t_c - t_b``) the change
    ``Δv = (u_c - u_b) / δ2 - (u_b - u_a) / δ1`` has, under the model

    - noise: ``σ_Δv = σ √(1/δ1² + (1/δ1 + 1/δ2)² + 1/δ2²)`` per axis (three independent
      detections of noise ``σ`` per axis);
    - model: ``|Δv| <= ½ (δ1 + δ2) max|ü|`` (exact for a constant ``ü``), and the image of a
      ballistic ball (acceleration of norm ``g``, speed ``|V|``, depth ``Z``, normalised
      image offset ``x``) has ``ü = f (a_xy - x a_z) / Z - 2 (Ż / Z) u̇``, so
      ``|ü| <= (f g √(1 + |x|²) + 2 |V| |u̇|) / Z``.

    A bend ``|Δv| > 5 σ_Δv + ½ (δ1 + δ2) |ü|max`` is a change of motion (probability under the
    model ``exp(-25/2) ≈ 4e-6``, as for :func:`failed_predictions`). A point is refused when

    - for either past point, the partner's triplet ``(before prev, prev, next)`` bends, and
      the triplet ``(prev, next, after next)``, where it is already available (not after the
      newest detection), bends too (a kink between ``prev`` and ``next`` bends both; one
      before ``prev`` only the first);
    - the newest camera's own triplet ending at the newest detection bends (a kink inside
      eq. (2)'s prediction span that the innovation test cannot see along the newest ray).

    Causality: only rows not after the newest detection, and within ``2 max_gap`` of it (the
    rows :class:`~pslog.fusion.pseudo.TypeAStream` keeps), are used, so a stream decides as
    the batch run does. (:func:`~pslog.fusion.pseudo.fuse_type_a` runs this test point by
    point inside type A's kernel, :func:`~pslog.fusion._pseudo_kernel._kinked`, the same
    arithmetic on the same tables; this columnar entry serves other callers and the
    tests.) ``|V|`` is the speed between the two past points, ``Z`` the depth of the past
    point (of the prediction for the newest camera).

    Parameters
    ----------
    prep : pslog.fusion._prepare.Prepared, the session's observations
    events : (k,) int, rows of the newest detections
    past : (P_{t-1}, P_{t-2}, predicted), two PseudoStereoPoints of k rows and (k, 3) metres
    noise_px : float, (k,) float or None, the detections' noise per image axis, pixels
        (None: 0.5; an array: each point's, :meth:`NoiseEstimate.sigmas`)
    max_gap_ns : int, the largest bridged gap, nanoseconds

    Returns
    -------
    (k,) bool, True where a bend is detected in an interval the point relies on
    """
    from . import _pseudo_kernel  # (numba: imported at the first use)

    p1, p2, predicted = past
    k = len(events)
    sigma = np.ascontiguousarray(np.broadcast_to(
        DEFAULT_NOISE_PX if noise_px is None else np.asarray(noise_px, dtype=np.float64),
        (k,)), dtype=np.float64)
    before, after = previous_next_rows(prep)
    # per camera: fx, fy, cx, cy, the optical axis R[2] and t[2] (the depth of a point)
    lens = prep.lens_rows

    # (views as they are, strided or not: the kernel reads a few entries per point, and
    # copying the (k,) columns out of type A's tables cost more than the kernel's reads)
    def ints(x):
        return np.asarray(x, dtype=np.int64)

    def floats(x):
        return np.asarray(x, dtype=np.float64).reshape(-1, 3)

    # point by point, each from its own rows (compiled; no (k,) temporaries per triplet, so
    # a 90-minute match needs no blocks; the same bits in a stream as in the batch run)
    kinked = np.zeros(k, dtype=bool)
    time_ns = ints(prep.obs.time_ns)
    uv = np.asarray(prep.uv_undistorted, dtype=np.float64)
    # each row's triplet terms once (most points' tests read three triplets, each read by
    # several points): _pseudo_kernel.bend_rows
    change, root = np.empty(len(time_ns)), np.empty(len(time_ns))
    _pseudo_kernel.bend_rows(time_ns, uv, before, after, NS, change, root)
    _pseudo_kernel.kink_kernel(
        ints(events), ints(p1.row), ints(p1.prev_row), ints(p1.next_row),
        floats(p1.points_world), ints(p2.row), ints(p2.prev_row), ints(p2.next_row),
        floats(p2.points_world), floats(predicted), sigma, before, after, time_ns, uv,
        ints(prep.obs.camera), lens, int(max_gap_ns), NS, kinked, change, root)
    return kinked
