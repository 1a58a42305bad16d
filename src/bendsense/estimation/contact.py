"""Contact at an unknown location: one s_c per quasi-static window, a force per frame (docs/theory.md, "Contact").

:func:`bendsense.estimate_contact` and ``estimate_force(load="contact", contact_s_m=None)``
run this module with ``estimate_force`` passed in.

A load along the body moves the coil angles the way a tip load does, except beyond s_c,
where the actuator bends freely: the location shows in the few coils past it, at a
fraction of a noise σ per frame. Over a window of n frames of one hold the sensor noise
of the mean shape falls as 1/√n while the load stays, so the location is fitted on the
window's mean:

1. the windows are the window test's (:mod:`bendsense.tracking.windows`: gaps, pressure
   steps, ``window_s``); the mean coil curvatures and pressure of each window's usable
   frames are one "frame" to fit;
2. for s_c on a grid (the coils past the first, and L) the known-location estimate
   (``estimate_force(load="contact", contact_s_m=s)``) fits the force at the mean, and
   ``T(s) = r̄ᵀ Ω r̄`` scores it: the window test's statistic of the mean residual with the
   covariance ``C`` of a mean over n frames (sensor noise / n, the calibration and
   model-parameter parts whole; ``Ω`` its pseudo-inverse on the complement of the force
   directions, :func:`~bendsense.tracking.windows.window_metric`);
3. from the grid's best, Gauss–Newton steps in s_c with the location's direction
   ``a = ∂(model coil angle)/∂s_c`` (``contact_jacobian_rad_per_m``): ``δs = aᵀΩr̄ /
   aᵀΩa``, kept where T falls;
4. ``σ(s_c)² = 1 / aᵀΩa``: the estimator minimises T, whose metric is C's own inverse
   (``ΩCΩ = Ω``), so its sandwich covariance is the Fisher form with the full budget;
   its parts (noise, calibration, parameters) are ``aᵀΩ C_p Ω a / (aᵀΩa)²``;
5. the model choice: ``Δ = T(L) − T(ŝ)`` (tip versus the best contact; a tip load is
   s_c = L, the boundary of the location's range, so under a tip load Δ follows
   ½χ²₀ + ½χ²₁): the window is a contact when ``Δ > LR_THRESHOLD`` (5.41: a tip window
   is taken for a contact with probability 1 % under the model);
6. every frame of a contact window is estimated at ŝ; its force covariance gains
   ``g gᵀ σ(s_c)²`` (each part its own), ``g = ∂F/∂s_c`` by central differences at the
   window's mean, and the covariance between the frame's own error and ŝ's (for a 2-D
   force; a 1-D constraint's is left out, :func:`_force_slope`);
7. the force and σ cover every hypothesis the window did not rule out, never the chosen
   one's alone (DESIGN section 2c, "Honest model choice"): the tip and a contact
   anywhere, weighed by their evidence (the window likelihood ``exp(−T/2)``, integrated
   over the contact's location), give a mixture whose mean and covariance the frames
   report (:func:`_mixture`); a window the data decide keeps its chosen force and σ.
   tools/contact_eval.py measures the coverage this gives.

A location the data cannot resolve — ``σ(s_c)`` beyond the length of the segment it
lies in, the force within ``TANGENT_DEG`` of the tangent at ŝ (the reconstructed
shape's), or ŝ beyond the last coil — is reported with ``contact_std_m = inf`` and the
message ``contact_unresolved: ...`` (a success: the force is kept). A window that keeps
the tip model reports its frames' tip estimates with ``contact_s_m`` and
``contact_std_m`` NaN, as for ``load="tip"`` (no contact along the body was found).
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from bendsense import _jit
from bendsense.errors import ArgumentError
from bendsense.status import Status
from bendsense.tracking import _window_kernels
from bendsense.tracking import windows as _win
from bendsense.validation import float_array, short

__all__ = ["LR_THRESHOLD", "TANGENT_DEG", "contact_windows"]

#: Δ = T(L) − T(ŝ) above this chooses a contact: P(½χ²₀ + ½χ²₁ > 5.41) = 1 % (a tip load taken for a contact).
LR_THRESHOLD = 5.41
#: A force within this angle [deg] of the tangent at ŝ does not place the contact.
TANGENT_DEG = 15.0
GN_STEPS = 4  # Gauss–Newton steps in s_c from the grid's best
FD_STEP_M = 5e-4  # central difference of the force in s_c [m]


def contact_windows(t_s, pressure_pa, window_s, B):
    """Window boundaries (W + 1,) of ``B`` frames as :func:`estimate_contact` cuts them.

    The window test's windows (:func:`bendsense.check_windows`: gaps, pressure steps,
    ``window_s``); one window of all frames without times.

    Parameters
    ----------
    t_s : array_like, shape (B,) or None
        Time of each frame [s].
    pressure_pa : array_like, shape (B,) or None
        Pressure of each frame [Pa]: a step starts a new segment.
    window_s : float
        Window length [s].
    B : int
        The number of frames.
    """
    if t_s is None:
        return np.array([0, B], dtype=np.int64)
    t, P, window_s = _win.time_inputs(B, t_s, window_s, pressure_pa)
    starts = _win.segment_starts(t, P, window_s, _win.reference_interval(t))
    return _win.window_bounds(t, starts, window_s)


def estimate_windows(estimate, shape, pressure_pa, config, calibration, t_s, window_s, options, threshold):
    """:func:`bendsense.estimate_contact`: the location per window, the force per frame, by ``estimate``.

    Parameters
    ----------
    estimate : callable
        :func:`bendsense.estimate_force` (passed in: this module does not import the
        package that delegates to it).
    shape, pressure_pa, config, calibration, t_s, window_s, threshold
        As :func:`bendsense.estimate_contact` takes them.
    options : dict
        Further options of ``estimate`` (``constraint``, ``noise_std``...).
    """
    t_start = time.perf_counter()
    config, kappa, batch = _inputs(shape, config)
    B = kappa.shape[0]
    if B == 0:  # as estimate_force says it
        raise ArgumentError(f"shape: no frames to estimate (batch shape {batch})")
    try:
        P = np.array(np.broadcast_to(np.asarray(pressure_pa, dtype=float), (B,)))
    except (TypeError, ValueError):
        raise ArgumentError(f"pressure_pa: expected {B} pressures [Pa] (one per frame), got {short(pressure_pa)}") \
            from None
    if len(batch) > 1:
        raise ArgumentError(f"shape: expected the frames of a time series (B, N) or one frame (N,), got batch shape "
                            f"{batch}")
    if isinstance(threshold, bool) or not isinstance(threshold, (int, float, np.integer, np.floating)) \
            or not threshold >= 0:
        raise ArgumentError(f"threshold: expected a Δχ² >= 0, got {short(threshold)}")
    bounds = contact_windows(t_s, P, window_s, B)
    est = locate(estimate, kappa, P, bounds, config, dict(options, calibration=calibration), float(threshold))
    est = dataclasses.replace(est, wall_time_s=time.perf_counter() - t_start)
    return est if batch else _one(est)


def estimate_frames(estimate, shape, pressure_pa, config, options, threshold=LR_THRESHOLD):
    """``estimate_force(load="contact", contact_s_m=None)``: every frame its own window (a mean of one frame).

    Parameters
    ----------
    estimate : callable
        :func:`bendsense.estimate_force`.
    shape : Shape or array_like, shape (..., N)
        Shapes or segment curvatures [1/m]; leading axes are frames.
    pressure_pa : array_like
        Pressure of each frame [Pa]; broadcasts against the frames.
    config : Config or None
        The actuator (None: the paper's prototype).
    options : dict
        ``estimate_force``'s options (``constraint``, ``calibration``, ``noise_std``...).
    threshold : float
        The model choice's threshold (:data:`LR_THRESHOLD`).
    """
    t_start = time.perf_counter()
    config, kappa, own = _inputs(shape, config)
    P = float_array("pressure_pa", pressure_pa)
    try:
        batch = np.broadcast_shapes(own, P.shape)
    except ValueError:
        raise ArgumentError(f"pressure_pa: shape {P.shape} does not broadcast against the shape's frames "
                            f"{batch}") from None
    B = int(np.prod(batch)) if batch else 1
    N = kappa.shape[-1]
    kappa = np.ascontiguousarray(np.broadcast_to(kappa.reshape(*own, N), (*batch, N)).reshape(B, N))
    P = np.ascontiguousarray(np.broadcast_to(P, batch).reshape(B))
    est = locate(estimate, kappa, P, np.arange(B + 1, dtype=np.int64), config, options, threshold)
    est = dataclasses.replace(est, wall_time_s=time.perf_counter() - t_start)
    return _reshape(est, B, batch)


def _reshape(est, B, batch):
    """An estimate of ``B`` flat frames shaped to ``batch``."""
    if not batch:
        return _one(est)
    changes = {f.name: getattr(est, f.name).reshape(*batch, *getattr(est, f.name).shape[1:])
               for f in dataclasses.fields(est)
               if isinstance(getattr(est, f.name), np.ndarray) and getattr(est, f.name).shape[:1] == (B,)}
    return dataclasses.replace(est, **changes)


def _inputs(shape, config):
    """The config, the curvatures (B, N) and the frames' batch shape of ``shape``."""
    if config is None:
        from bendsense.config import load_config

        config = load_config()
    kappa = getattr(shape, "curvature_per_m", shape)
    kappa = float_array("shape", kappa)
    N = len(config.sensor.lengths_m)
    if kappa.ndim == 0 or kappa.shape[-1] != N:
        raise ArgumentError(f"shape: expected segment curvatures (..., {N}) [1/m] or a Shape, got shape "
                            f"{kappa.shape}")
    batch = kappa.shape[:-1]
    return config, np.ascontiguousarray(kappa.reshape(-1, N)), batch


def _one(est):
    """A one-frame estimate (batch shape ``()``) of a series of one frame."""
    changes = {f.name: getattr(est, f.name)[0] for f in dataclasses.fields(est)
               if isinstance(getattr(est, f.name), np.ndarray) and f.name not in ("shifts_m",)}
    if isinstance(est.shifts_m, np.ndarray):
        changes["shifts_m"] = est.shifts_m[0]
    changes["message"] = str(np.asarray(est.message).reshape(-1)[0])
    return dataclasses.replace(est, **changes)


def _grid(config):
    """The coarse grid of s_c [m]: the coils past the first one on the actuator, and L."""
    L = float(config.actuator.length_m)
    ends = np.cumsum(config.sensor.lengths_m)
    ends = ends[(ends > ends[0]) & (ends < L * (1 - 1e-9))]
    return np.append(ends, L)


def locate(estimate_force, kappa, P, bounds, config, options, threshold):
    """The estimate of frames ``kappa`` (B, N) at pressures ``P`` (B,) with one location per window ``bounds``."""
    L = float(config.actuator.length_m)
    W = bounds.size - 1
    counts = np.diff(bounds)
    kbar, Pbar, n = _means(kappa, P, bounds)
    grid = _grid(config)
    G = grid.size

    def fit(rows, s):  # the known-location estimate at the windows' means ``rows`` and the metric there
        e = estimate_force(kbar[rows], Pbar[rows], config, load="contact", contact_s_m=s, warm_start=False, **options)
        return e, _metric(e, n[rows])[:4]

    rows = np.repeat(np.arange(W), G)
    e0, (T, er, ee, parts) = fit(rows, np.tile(grid, W))
    if e0.uncertainty == "none" or e0.residual_rad is None:
        raise ArgumentError("noise_std: estimate_contact weighs the location by the noise model (a calibration with "
                            "its flat-recording noise, or noise_std > 0) and fits the coil angles "
                            "(objective='angles'); got none")
    T, er, ee, parts = (a.reshape(W, G, *a.shape[1:]) for a in (T, er, ee, parts))
    Tg = np.where(np.isfinite(T), T, np.inf)
    best = np.argmin(Tg, axis=1)
    w = np.arange(W)
    s_hat, T_hat, er_hat, ee_hat, parts_hat = grid[best], Tg[w, best], er[w, best], ee[w, best], parts[w, best]
    forces, covs = e0.force_n.reshape(W, G, 2), e0.covariance_parts_n2.reshape(W, G, 3, 2, 2)
    force_hat, cov_hat = forces[w, best], covs[w, best]
    shifts_hat = e0.shifts_m.reshape(W, G, -1)[w, best]
    T_tip = Tg[:, -1]
    step = np.full(W, np.diff(grid).max())
    for _ in range(GN_STEPS):  # Gauss–Newton in s_c from the grid's best, kept where T falls
        delta = np.clip(np.nan_to_num(er_hat / ee_hat), -step, step)
        trial = np.clip(s_hat + delta, grid[0], L)
        move = np.isfinite(T_hat) & (np.abs(trial - s_hat) > 1e-7)
        if not move.any():
            break
        e1, (T1, er1, ee1, p1) = fit(w[move], trial[move])
        better = np.zeros(W, dtype=bool)
        better[move] = T1 < T_hat[move]
        idx = np.flatnonzero(better)
        sub = better[move]
        s_hat[idx], T_hat[idx], er_hat[idx], ee_hat[idx] = trial[idx], T1[sub], er1[sub], ee1[sub]
        parts_hat[idx], force_hat[idx], shifts_hat[idx] = p1[sub], e1.force_n[sub], e1.shifts_m[sub]
        cov_hat[idx] = e1.covariance_parts_n2[sub]
        step = np.where(better, step, 0.5 * step)
    contact = np.isfinite(T_hat) & (T_tip - T_hat > threshold) & (s_hat < L)
    var_s = np.where(ee_hat > 0, 1.0 / ee_hat, np.inf)
    var_parts = parts_hat / np.where(ee_hat > 0, ee_hat * ee_hat, np.nan)[:, None]
    g, cross = _force_slope(fit, lambda e: _metric(e, np.tile(n[contact], 3)), w[contact], s_hat[contact],
                            grid[0], L)
    why = _unresolved(config, s_hat, var_s, force_hat, shifts_hat)
    s_frames = np.repeat(np.where(contact, s_hat, L), counts)
    est = estimate_force(kappa, P, config, load="contact", contact_s_m=s_frames, **options)
    mix = _mixture(grid, Tg, forces, covs, (s_hat, T_hat, force_hat, cov_hat, var_s), contact)
    return _finish(est, bounds, contact, s_hat, var_s, var_parts, (g, cross), why, (grid[0], L), mix)


def _mixture(grid, T, forces, covs, refined, contact):
    """The force's shift (W, 2) and added covariance parts (W, 3, 2, 2) that cover every hypothesis the window allows.

    The hypotheses are the tip (s_c = L) and a contact anywhere in ``[grid[0], L)``, each
    with prior probability ½ and the location uniform. A hypothesis' evidence is its
    window likelihood ``exp(−T/2)`` (``T``: the window statistic of the window's mean,
    ``T`` (W, G) on the grid); a contact's is integrated over the location: the grid
    points each stand for their cell, and the refined ŝ (``refined``: ŝ, T(ŝ), the force
    and its covariance parts at the mean, σ²(s_c)) replaces the grid point nearest to it,
    its cell narrowed to the Laplace width ``√(2π) σ(s_c)`` of a sharp optimum. With the
    weights ``w_h``, the mixture's mean ``F̄ = Σ w_h F_h`` and covariance ``Σ w_h (C_h +
    (F_h − F̄)(F_h − F̄)ᵀ)``; against the chosen hypothesis' (the window's ŝ or the tip)
    this shifts the force by ``F̄ − F_chosen`` and adds the spread of the hypotheses'
    forces to the model part and, per part, what the others' covariances hold beyond the
    chosen one's (its positive part). Where the data decide (one weight ≈ 1) both vanish.
    """
    s_hat, T_hat, f_hat, c_hat, var_s = refined
    W, G = T.shape
    L = grid[-1]
    edges = np.concatenate([[grid[0]], 0.5 * (grid[1:-1] + grid[:-2]) if G > 2 else [], [L]])
    cell = np.diff(edges) if G > 1 else np.zeros(0)  # the contact points' cells (the grid but L)
    Th = np.concatenate([T, T_hat[:, None]], axis=1)
    F = np.concatenate([forces, f_hat[:, None]], axis=1)
    C = np.concatenate([covs, c_hat[:, None]], axis=1)
    width = np.zeros((W, G + 1))
    width[:, :G - 1] = cell
    near = np.argmin(np.abs(grid[None, :] - s_hat[:, None]), axis=1)
    swap = (near < G - 1) & np.isfinite(T_hat)
    rows = np.flatnonzero(swap)
    width[rows, G] = np.minimum(cell[near[rows]], np.sqrt(2.0 * math.pi * var_s[rows]))
    width[rows, near[rows]] = 0.0
    span = L - grid[0]
    with np.errstate(divide="ignore"):
        logw = -0.5 * Th + np.log(width / span if span > 0 else width)
        logw[:, G - 1] = -0.5 * T[:, -1]  # the tip: a point of prior mass ½ (the contact's ½ is its integral)
    logw = np.where(np.isfinite(logw) & np.isfinite(F).all(axis=-1), logw, -np.inf)
    top = logw.max(axis=1, keepdims=True)
    wts = np.where(np.isfinite(top), np.exp(logw - np.where(np.isfinite(top), top, 0.0)), 0.0)
    total = wts.sum(axis=1, keepdims=True)
    wts = np.divide(wts, total, out=np.zeros_like(wts), where=total > 0)
    chosen = np.where(contact, G, G - 1)
    idx = np.arange(W)
    finite = np.isfinite(C).all(axis=(2, 3, 4))
    Fz, Cz = np.nan_to_num(F), np.where(finite[..., None, None, None], C, 0.0)
    mean = np.einsum("wh,whi->wi", wts, Fz)
    dev = Fz - mean[:, None]
    spread = np.einsum("wh,whi,whj->wij", wts, dev, dev)
    beyond = np.einsum("wh,whpij->wpij", wts, Cz) - Cz[idx, chosen]
    lam, V = np.linalg.eigh(beyond)
    beyond = np.einsum("wpik,wpk,wpjk->wpij", V, np.maximum(lam, 0.0), V)
    beyond[:, 2] += spread
    beyond[np.any((wts > 1e-9) & ~finite, axis=1), 2] = np.diag([np.inf, np.inf])  # a hypothesis without a σ
    decided = ~(total[:, 0] > 0) | ~np.isfinite(F[idx, chosen]).all(axis=-1)
    shift = np.where(decided[:, None], 0.0, mean - Fz[idx, chosen])
    beyond[decided] = 0.0
    return shift, beyond


def _means(kappa, P, bounds):
    """Each window's mean curvatures (W, N) and pressure (W,) over its usable (finite) frames, and their number."""
    ok = np.isfinite(kappa).all(axis=1) & np.isfinite(P)
    k = np.where(ok[:, None], kappa, 0.0)
    c = np.add.reduceat(ok.astype(float), bounds[:-1]) if kappa.shape[0] else np.zeros(0)
    n = c.astype(np.int64)
    safe = np.maximum(c, 1.0)
    kbar = np.add.reduceat(k, bounds[:-1], axis=0) / safe[:, None]
    Pbar = np.add.reduceat(np.where(ok, P, 0.0), bounds[:-1]) / safe
    kbar[n == 0] = np.nan  # a window without a usable frame: no location (its frames fail on their own)
    Pbar[n == 0] = np.median(P[np.isfinite(P)]) if np.isfinite(P).any() else 0.0
    return kbar, Pbar, n


def _metric(est, n):
    """T, aᵀΩr̄, aᵀΩa, the parts (K, 3) and X (K, 2, 5) of an estimate of K windows' means.

    Each mean is over ``n`` (K,) frames (:func:`~bendsense.tracking.windows.window_metric`).
    """
    K = n.size
    out = (np.empty(K), np.empty(K), np.empty(K), np.empty((K, 3)), np.empty((K, 2, 5)))
    if est.residual_rad is None or est.shift_errors is None or est.uncertainty != "propagated":
        return tuple(np.full_like(a, np.nan) for a in out)
    pay = est.residual_rad, est.jacobian_rad_per_n, est.model_factor_rad, est.shifts_m, est.contact_jacobian_rad_per_m
    c = np.ascontiguousarray
    _jit.call(_window_kernels.window_metrics, *(c(a, dtype=float) for a in pay),
              c(n, dtype=np.int64), tuple(est.shift_errors), np.asarray(est.coils, dtype=np.int64),
              float(est.strip_gap_m), *out)
    return out


def _force_slope(fit, metric, rows, s, lo, hi):
    """∂F/∂s_c (K, 2) at the means of ``rows``, and the covariance parts (K, 3, 2) of the frames' force with ŝ.

    ∂F/∂s_c by a central difference (one-sided at the ends of [lo, hi]); the force is at a known location.

    The cross term ``Cov(δF, δŝ)_p = D (ĀᵀWĀ)⁺ ĀᵀW C_p Ω a / aᵀΩa`` (X of
    :func:`~bendsense.tracking.windows.window_metric`) for a 2-D force (D = I); a 1-D
    constraint's force direction is not in the payload: its cross term is left out.
    """
    K = rows.size
    if K == 0:
        return np.zeros((0, 2)), np.zeros((0, 3, 2))
    a, b = np.maximum(s - FD_STEP_M, lo), np.minimum(s + FD_STEP_M, hi)
    e, _ = fit(np.concatenate([rows, rows, rows]), np.concatenate([a, b, s]))
    F = e.force_n.reshape(3, K, 2)
    g = (F[1] - F[0]) / (b - a)[:, None]
    _, _, ee, _, X = (m[2 * K:] for m in metric(e))
    cross = np.zeros((K, 3, 2))
    two = np.any(np.asarray(e.jacobian_rad_per_n)[2 * K:, :, 1] != 0.0, axis=1)
    for i in np.flatnonzero(two & np.isfinite(X).all(axis=(1, 2)) & (ee > 0)):
        cross[i] = (np.linalg.pinv(X[i, :, 3:]) @ X[i, :, :3]).T / ee[i]
    return g, cross


def _unresolved(config, s_hat, var_s, force, shifts):
    """Why each window's location is not resolved (W,) (an empty string where it is)."""
    lengths = np.asarray(config.sensor.lengths_m, dtype=float)
    ends = np.cumsum(lengths)
    gap = float(config.sensor.strip_gap_m)
    seg = np.minimum(np.searchsorted(ends, s_hat), lengths.size - 1)
    sigma = np.sqrt(var_s)
    # the tangent at ŝ of the reconstructed mean shape: the coil angles S/d, φ(0) = 0, linear between coils
    phi = np.array([np.interp(s, np.append(0.0, ends), np.append(0.0, sh / gap)) for s, sh in zip(s_hat, shifts)])
    t = np.stack([np.sin(phi), np.cos(phi)], axis=-1)
    mag = np.hypot(*force.T)
    along = np.abs(np.sum(force * t, axis=-1)) > np.cos(math.radians(TANGENT_DEG)) * mag
    why = np.full(s_hat.size, "", dtype=object)
    for i in range(s_hat.size):
        if not np.isfinite(sigma[i]) or sigma[i] > lengths[seg[i]]:
            why[i] = (f"σ(s_c) = {1e3 * sigma[i]:.3g} mm beyond the {1e3 * lengths[seg[i]]:.3g} mm segment it lies in")
        elif along[i]:
            why[i] = f"the force within {TANGENT_DEG:g}° of the tangent at s_c"
        elif s_hat[i] > ends[-1]:
            why[i] = f"s_c beyond the last coil at {1e3 * ends[-1]:.4g} mm"
    return why


def _finish(est, bounds, contact, s_hat, var_s, var_parts, slope, why, span, mixture):
    """``est`` (the frames at their windows' locations) with the location, its σ, its part of the force's σ.

    Per part p of the budget: ``g gᵀ σ_p(s_c)² + c_p gᵀ + g c_pᵀ`` with ``g = ∂F/∂s_c`` and
    ``c_p`` the frames' force covariance with ŝ (:func:`_force_slope`); then the
    hypotheses the window did not rule out (``mixture``: the force's shift and the added
    covariance parts per window, :func:`_mixture`). ``span``: the arc lengths a contact
    may lie in, (first grid point, L) [m].
    """
    lo, L = span
    counts = np.diff(bounds)
    B = int(bounds[-1])
    rep = lambda a: np.repeat(a, counts, axis=0)  # noqa: E731 (per window → per frame)
    var_cap = np.minimum(var_s, (L - lo) ** 2 / 12.0)  # the force's part: at most a location uniform over the span
    capped = ~(var_s <= var_cap)
    parts_w = np.where(np.isfinite(var_parts), var_parts, 0.0)
    parts_w *= (var_cap / np.maximum(parts_w.sum(axis=1), 1e-300))[:, None]
    gw, cw = np.zeros((contact.size, 2)), np.zeros((contact.size, 3, 2))
    gw[contact], cw[contact] = slope
    cw[capped] = 0.0
    gc = gw[:, None, :, None] * cw[:, :, None, :]  # (W, 3, 2, 2): g c_pᵀ
    add_w = gw[:, None, :, None] * gw[:, None, None, :] * parts_w[:, :, None, None] + gc + np.swapaxes(gc, -1, -2)
    add_parts = rep(add_w + mixture[1])  # (B, 3, 2, 2)
    cov_parts = est.covariance_parts_n2 + add_parts
    cov = est.covariance_n2 + add_parts.sum(axis=1)
    var = est.std_n ** 2 + np.diagonal(add_parts.sum(axis=1), axis1=-2, axis2=-1)
    std = np.sqrt(np.maximum(var, 0.0))  # inf stays inf
    unres = contact & (why != "")
    s_m = np.where(contact, s_hat, np.nan)
    std_m = np.where(unres, np.inf, np.where(contact, np.sqrt(var_s), np.nan))
    message = np.array(np.broadcast_to(np.asarray(est.message, dtype=object), (B,)), dtype=object)
    frame_why = rep(np.where(unres, why, ""))
    frame_s = rep(s_m)
    unresolved = (frame_why != "") & (np.asarray(est.status) == Status.OK)
    for i in np.flatnonzero(unresolved):
        message[i] = (f"contact_unresolved: the data do not place the contact ({frame_why[i]}); the force is at the "
                      f"best location s_c = {1e3 * frame_s[i]:.4g} mm, contact_std_m inf")
    return dataclasses.replace(est, load="contact", contact_s_m=frame_s, contact_std_m=rep(std_m),
                               force_n=est.force_n + rep(mixture[0]), covariance_n2=cov, covariance_parts_n2=cov_parts,
                               std_n=std,
                               status=np.where(unresolved, Status.CONTACT_UNRESOLVED, est.status).astype(np.int8),
                               message=message.astype(str))
