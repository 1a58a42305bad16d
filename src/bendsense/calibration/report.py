"""A calibration in words and in a picture: the text of ``bendsense calibrate`` and the fit's plot."""

from __future__ import annotations

import numpy as np

from bendsense.calibration.polynomials import parity_masks, polyval_shift

__all__ = []


def report(cal) -> str:
    """Summarise a calibration as text (:meth:`Calibration.report`).

    Parameters
    ----------
    cal : Calibration
        The calibration.

    Returns
    -------
    str
        Degree, coefficients, ranges, per-strip residuals, CV table.
    """
    lines = [
        f"calibration: {cal.n_channels} channels, degree {cal.degree}, weighting {cal.weighting}, "
        f"kappa_cal = 1/{'(R + c)' if cal.sleeve else 'R'}",
        "  f_odd  coefficients (ascending): " + ", ".join(f"{c:.6g}" for c in cal.coefficients_odd),
        "  f_even coefficients (ascending): " + ", ".join(f"{c:.6g}" for c in cal.coefficients_even),
        f"  fitted dA range: odd [{cal.delta_a_range_odd[0]:.6g}, {cal.delta_a_range_odd[1]:.6g}], "
        f"even [{cal.delta_a_range_even[0]:.6g}, {cal.delta_a_range_even[1]:.6g}]",
        "  flat noise std (mean over channels): "
        + (f"{float(np.mean(cal.noise_std)):.4g}" if cal.noise_known else "not measured"),
    ]
    if cal.strip_residuals:
        lines.append("  strip   R [mm]  kappa [1/m]  rms dS [um]  max dS [um]  frames  recording")
        for i, r in enumerate(cal.strip_residuals):
            lines.append(
                f"  {i:5d} {r.radius_m * 1e3:8.2f} {r.curvature_per_m:12.3f} {r.rms_shift_m * 1e6:12.3f} "
                f"{r.max_abs_shift_m * 1e6:12.3f} {r.n_frames:7d}  {r.recording}"
            )
    if cal.cv_errors_m:
        lines.append("  degree  CV rms dS [um] (leave one strip out)")
        for d, e in sorted(cal.cv_errors_m.items()):
            mark = "  <- chosen" if d == cal.degree else ""
            lines.append(f"  {d:6d} {e * 1e6:15.3f}{mark}")
    return "\n".join(lines)


def plot(cal, ax=None):
    """Plot the fitted polynomials over the data and the residuals (:meth:`Calibration.plot`).

    Parameters
    ----------
    cal : Calibration
        The calibration.
    ax : matplotlib.axes.Axes, optional
        Draw the fit only, on it.

    Returns
    -------
    ax or (2,) array of axes
    """
    import matplotlib.pyplot as plt

    axes = None
    if ax is None:
        _, axes = plt.subplots(2, 1, sharex=True, figsize=(6, 6))
        ax = axes[0]
    odd, even = parity_masks(cal.n_channels)
    for mask, coef, rng, name, color in (
        (odd, cal.coefficients_odd, cal.delta_a_range_odd, "odd", "C0"),
        (even, cal.coefficients_even, cal.delta_a_range_even, "even", "C1"),
    ):
        if not np.any(mask):
            continue
        x = np.linspace(rng[0], rng[1], 200)
        ax.plot(x, polyval_shift(coef, x) * 1e3, color=color, label=f"f_{name} ({name} channels)")
        if cal.fit_delta_a is not None:
            dx, sy = cal.fit_delta_a[:, mask], cal.fit_shifts_m[:, mask]
            ax.plot(dx.ravel(), sy.ravel() * 1e3, ".", color=color, alpha=0.6, label=f"strips, {name} channels")
            if axes is not None:
                r = (polyval_shift(coef, dx) - sy) * 1e6
                axes[1].plot(dx.ravel(), r.ravel(), ".", color=color)
    ax.set_ylabel("shift S [mm]")
    ax.set_title(f"calibration fit, degree {cal.degree} (paper eq. 2)", fontsize="medium")
    ax.legend(fontsize="small")
    if axes is not None:
        axes[1].axhline(0.0, color="k", linewidth=0.5)
        axes[1].set_ylabel("residual f(ΔA) − S [µm]")
        axes[1].set_xlabel("ΔA = A − A0 [signal units]")
        return axes
    ax.set_xlabel("ΔA = A − A0 [signal units]")
    return ax
