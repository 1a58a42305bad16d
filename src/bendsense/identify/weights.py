"""Stiffness from a session of hanging weights recorded with bendsense (paper section V-C).

A session of hanging weights: the known tip force of each frame in the columns ``fx_n,
fy_n`` (base frame, as ``bendsense simulate tip-loads`` writes them) or ``mass_kg`` (``F =
m g ĝ`` with ``g`` and ``ĝ`` of the config's gravity). The frames with a load (``|F| > 0``)
and a usable shape (:func:`bendsense.identify.sessions.session_shapes`) become rows of
:class:`~bendsense.identify.StiffnessData` whose measured points are the reconstructed
shape at the coils (arc lengths ``L_i``); :func:`bendsense.identify.fit_stiffness` fits EI
per pressure level and the line EI(P), with the calibration's error common to all rows
(:func:`bendsense.identify.covariance.session_covariance`).
"""

from __future__ import annotations

import warnings

import numpy as np

from bendsense.config import FREE_BENDING_PARAMETERS
from bendsense.errors import DataWarning, SessionError
from bendsense.identify import StiffnessData
from bendsense.identify.covariance import session_covariance
from bendsense.identify.sessions import _block, _source, session_shapes

__all__ = ["fit_stiffness_session", "stiffness_data_from_session"]


def stiffness_data_from_session(session, calibration, config=None):
    """The loaded frames of a hanging-weight session as stiffness data (module docstring).

    Parameters
    ----------
    session : Session or path
        The recording, with the pressure of every frame and the known tip force in the
        columns ``fx_n, fy_n`` [N] or ``mass_kg`` [kg].
    calibration : Calibration or path
        The sensor's calibration.
    config : Config or path, optional
        Sensor, actuator and gravity; default the paper's.

    Returns
    -------
    StiffnessData
        One row per usable loaded frame, the reconstructed points at the coils.

    Raises
    ------
    SessionError
        No pressure, no load columns, or no usable loaded frame.
    """
    from bendsense.session.inputs import process_inputs

    session, config, calibration, _ = process_inputs(session, config, calibration, "")
    return _stiffness_rows(session, calibration, config)[0]


def _stiffness_rows(session, calibration, config):
    """The stiffness data of the session's loaded frames, and their frame indices."""
    force = _known_force(session, config)
    shape, usable = session_shapes(session, calibration, config)
    weighed = np.all(np.isfinite(force), axis=-1) & (np.hypot(force[:, 0], force[:, 1]) > 0)
    rows = np.flatnonzero(usable & weighed)
    left = weighed & ~usable
    if left.any() and rows.size:  # said, not silently fewer levels than the session holds
        p = np.asarray(session.pressure_pa, dtype=float)[left]
        warnings.warn(f"{_source(session)}: {int(left.sum())} of {int(weighed.sum())} loaded frames not used: their "
                      f"signals outside the calibrated range or their pressure outside actuator.pressure_range_pa "
                      f"({np.nanmin(p) / 1e3:g}..{np.nanmax(p) / 1e3:g} kPa)", DataWarning, stacklevel=3)
    if rows.size == 0:
        raise SessionError(f"{_source(session)}: no frame with a known nonzero load and a usable shape "
                           "(in the calibrated range, its pressure in actuator.pressure_range_pa)")
    pos = np.asarray(shape.positions_m)[rows]
    s = np.broadcast_to(np.asarray(shape.s_m), (rows.size, pos.shape[1]))
    return StiffnessData(np.asarray(session.pressure_pa, dtype=float)[rows], force[rows], s, pos), rows


def fit_stiffness_session(session, calibration, config=None, **options):
    """Fit EI(P) to the hanging-weight frames of a session (module docstring).

    :func:`stiffness_data_from_session` gives the rows; :func:`bendsense.identify.fit_stiffness`
    fits them, with the levels' covariance from the calibration's errors over all rows
    (:func:`bendsense.identify.covariance.session_covariance` through the reconstructed
    points' sensitivity to the shifts): the calibration error is common to every frame
    and does not average down over them.

    Parameters
    ----------
    session : Session or path
        The recording (pressure and known tip force of every frame).
    calibration : Calibration or path
        The sensor's calibration.
    config : Config or path, optional
        With the free-bending model identified first; default the paper's.
    **options
        ``fix``, ``pressure_tolerance_pa``, ``weighted``, ``method`` of
        :func:`~bendsense.identify.fit_stiffness`.

    Returns
    -------
    StiffnessFit
    """
    from bendsense.identify import fit_stiffness
    from bendsense.session.inputs import process_inputs

    session, config, calibration, _ = process_inputs(session, config, calibration, "")
    data, rows = _stiffness_rows(session, calibration, config)
    shifts = np.asarray(calibration.shifts_m(np.asarray(session.signals, dtype=float)[rows]))
    dpos_ds = _points_shift_jacobian(shifts, calibration.strip_gap_m(config.sensor), config)

    def level_covariance(sensitivity, level, level_ei):
        weights = np.einsum("nmc,nmcj->nj", sensitivity, dpos_ds)
        cov = session_covariance(calibration, shifts, weights, level, len(level_ei))
        g = _level_k0_jacobian(data, config, sensitivity, level, level_ei)
        return cov, g @ _block(config, FREE_BENDING_PARAMETERS) @ g.T

    return fit_stiffness(data, config, level_covariance=level_covariance, **options)


def _level_k0_jacobian(data, config, sensitivity, level, level_ei) -> np.ndarray:
    """∂EI of each level / ∂(μ̄, μ_s, prebend) (levels, 3): through K0(P) of each row's model shape.

    The level's EI minimises the distance of the model points to the measured ones; a
    change δK0 of a row's natural curvature moves its model points by ∂r/∂K0 δK0 and
    the fitted EI by −sensitivity · ∂r/∂K0 δK0 (∂r/∂K0 by a central difference).
    """
    from bendsense.mechanics.actuator import FreeBendingModel, model_jacobian
    from bendsense.mechanics.beam import solve_beam

    p = data.pressure_pa
    k0 = FreeBendingModel.from_config(config).tip_curvature_per_m(p)
    grid = data.s_m[0]
    ei = np.asarray(level_ei)[level]
    h = 1e-4 * np.maximum(np.abs(k0), 1.0)
    w = config.weight_per_length_n_per_m
    hi, lo = (np.asarray(solve_beam(config.actuator.length_m, ei, k0 + sign * h, data.force_n, w, s_m=grid,
                                    warn=False).positions_m) for sign in (1.0, -1.0))
    dei_dk0 = -np.einsum("nmc,nmc->n", sensitivity, (hi - lo) / (2.0 * h[:, None, None]))
    dk0 = model_jacobian(config, p, FREE_BENDING_PARAMETERS)[:, 0, :]  # (n, 3)
    out = np.zeros((len(level_ei), dk0.shape[1]))
    np.add.at(out, level, dei_dk0[:, None] * dk0)
    return out


def _points_shift_jacobian(shifts_m, gap_m: float, config, h: float = 1e-5) -> np.ndarray:
    """∂(PCC points at the coils)/∂S (n, N, 2, N) [m/m], by central differences in the curvatures."""
    from bendsense.shape.pcc import Shape

    lengths = np.asarray(config.sensor.segment_lengths_m, dtype=float)
    coils = np.cumsum(lengths)
    n, N = shifts_m.shape
    delta = np.diff(np.asarray(shifts_m, dtype=float), axis=-1, prepend=0.0)
    kappa = delta / (gap_m * lengths)
    bumped = np.repeat(kappa[:, None, :], 2 * N, axis=1)
    eye = np.eye(N) * h
    bumped[:, :N] += eye
    bumped[:, N:] -= eye
    pos = np.asarray(Shape.from_curvatures(bumped, lengths, s_m=coils).positions_m)  # (n, 2N, M, 2)
    dpos_dk = np.moveaxis((pos[:, :N] - pos[:, N:]) / (2 * h), 1, -1)  # (n, M, 2, N)
    # κ_i = (S_i − S_{i−1}) / (d l_i)
    dk_ds = (np.eye(N) - np.eye(N, k=-1)) / (gap_m * lengths)[:, None]
    return dpos_dk @ dk_ds


def _known_force(session, config) -> np.ndarray:
    """The tip force (frames, 2) [N] of the session's truth columns ``fx_n, fy_n`` or ``mass_kg``."""
    extra = session.extra
    has_f = [n for n in ("fx_n", "fy_n") if n in extra]
    if has_f and "mass_kg" in extra:
        raise SessionError(f"{_source(session)}: give the load as fx_n, fy_n or as mass_kg, not both")
    if len(has_f) == 1:
        other = "fy_n" if has_f == ["fx_n"] else "fx_n"
        raise SessionError(f"{_source(session)}: missing column {other} (the tip force needs fx_n and fy_n)")
    if has_f:
        return np.stack([np.asarray(extra["fx_n"], dtype=float), np.asarray(extra["fy_n"], dtype=float)], axis=-1)
    if "mass_kg" in extra:
        m = np.asarray(extra["mass_kg"], dtype=float)
        if np.any(m[np.isfinite(m)] < 0):
            raise SessionError(f"{_source(session)}: column mass_kg: a hanging mass cannot be negative")
        return m[:, None] * config.gravity.g_m_per_s2 * np.asarray(config.gravity.direction, dtype=float)
    raise SessionError(f"{_source(session)}: no load columns: give the known tip force as fx_n, fy_n [N] "
                       "or the hanging mass as mass_kg")
