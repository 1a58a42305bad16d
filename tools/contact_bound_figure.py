"""What a contact along the finger leaves resolvable: the Cramér–Rao bound over s_c and |F| (docs/contact.md).

Run from the repository root::

    python tools/contact_bound_figure.py [--out docs/img/contact-bound.png] [--pressure-kpa 60]
    python tools/contact_bound_figure.py --hidden-sensor 0    # the table for a hidden sensor of the tests

Draws ``bendsense.estimation.cramer_rao.contact_bound`` (the bound of the paper's prototype with the simulated
sensor at 1.5 counts) as σ(s_c) over s_c / L for several contact forces, one frame and a
50 ms window at 2 kHz (100 frames), for the two force models (``none``: both components
free; ``normal``: the magnitude along the contact normal), and prints the table of
docs/contact.md.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
FORCES_N = (0.05, 0.1, 0.2, 0.3)
TABLE_FRACTIONS = (0.3, 0.6, 0.8, 0.9)
TABLE_FORCES_N = (0.05, 0.2)
WINDOW_FRAMES = 100  # 50 ms at 2 kHz


def table(config, pressure_pa, noise_counts, calibration=None):
    """Rows (s_c / L, |F|, σ(s_c) one frame and window [mm], σ(F) known / unknown s_c [mN]) per constraint."""
    from bendsense.estimation.cramer_rao import contact_bound

    length = config.actuator.length_m
    sc = np.asarray(TABLE_FRACTIONS)[:, None] * length
    rows = []
    for constraint in ("none", "normal"):
        b = contact_bound(config, calibration, contact_s_m=sc, force_n=np.asarray(TABLE_FORCES_N),
                          pressure_pa=pressure_pa, noise_std=noise_counts, constraint=constraint)
        combined = (lambda a: a) if constraint == "normal" else (lambda a: np.hypot(*np.moveaxis(a, -1, 0)))
        force_known, force = combined(b.force_std_known_n), combined(b.force_std_n)
        for i, fr in enumerate(TABLE_FRACTIONS):
            for j, f in enumerate(TABLE_FORCES_N):
                one = b.contact_std_m[i, j]
                rows.append((constraint, fr, f, 1e3 * one, 1e3 * one / np.sqrt(WINDOW_FRAMES),
                             1e3 * force_known[i, j], 1e3 * force[i, j]))
    return rows


def figure(config, pressure_pa, noise_counts, out):
    """Draw σ(s_c) over s_c / L for the forces of FORCES_N, one frame and a 50 ms window, into ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from bendsense.estimation.cramer_rao import contact_bound

    length = config.actuator.length_m
    lengths = np.asarray(config.sensor.lengths_m, dtype=float)
    fractions = np.linspace(0.2, 1.0, 33)
    fine = np.linspace(0.2, 1.0, 801)
    ends = np.cumsum(lengths)
    segment = lengths[np.minimum(np.searchsorted(ends, fine * length), lengths.size - 1)]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.8), sharey=True)
    colors = plt.get_cmap("viridis")(np.linspace(0.0, 0.85, len(FORCES_N)))
    for constraint, style in (("none", "-"), ("normal", "--")):
        b = contact_bound(config, contact_s_m=fractions[:, None] * length, force_n=np.asarray(FORCES_N),
                          pressure_pa=pressure_pa, noise_std=noise_counts, constraint=constraint)
        for ax, frames, title in ((axes[0], 1, "one frame"), (axes[1], WINDOW_FRAMES, "50 ms window at 2 kHz")):
            for j, (f, c) in enumerate(zip(FORCES_N, colors, strict=True)):
                label = f"|F| = {f:g} N" if constraint == "none" else None
                ax.semilogy(fractions, 1e3 * b.contact_std_m[:, j] / np.sqrt(frames), style, color=c, label=label)
            ax.set_title(title)
    for ax in axes:
        ax.plot(fine, 1e3 * segment, color="tab:red", lw=1.0)
        ax.text(0.6, 1e3 * segment[0] * 1.15, "the segment at s_c: contact_unresolved above", fontsize=8,
                color="tab:red", ha="center")
        ax.set_xlabel("contact location s_c / L")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("Cramér–Rao σ(s_c) [mm]")
    handles, labels = axes[0].get_legend_handles_labels()
    from matplotlib.lines import Line2D

    handles += [Line2D([], [], color="k", ls="-"), Line2D([], [], color="k", ls="--")]
    labels += ["force components free (none)", "force along the normal (normal)"]
    fig.legend(handles, labels, fontsize=8, loc="lower center", ncol=3)
    fig.suptitle(f"What the sensor can tell about a contact: paper prototype at {pressure_pa / 1e3:g} kPa, "
                 f"simulated sensor, {noise_counts:g} counts", fontsize=10)
    fig.tight_layout(rect=(0, 0.12, 1, 1))
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)


def main(argv=None):
    """Draw the figure and print the table."""
    from bendsense.config import load_config

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "img" / "contact-bound.png")
    ap.add_argument("--pressure-kpa", type=float, default=60.0)
    ap.add_argument("--noise-counts", type=float, default=1.5)
    ap.add_argument("--no-figure", action="store_true", help="Only print the table.")
    ap.add_argument("--hidden-sensor", type=int, metavar="SEED",
                    help="Only the table, for the hidden sensor SEED of tests/forward_model.py through its fitted "
                         "calibration (tools/model_error.py's sensors, which tools/contact_eval.py scores on)")
    args = ap.parse_args(argv)
    config = load_config()
    p = args.pressure_kpa * 1e3
    cal = None
    if args.hidden_sensor is not None:
        import sys

        sys.path.insert(0, str(ROOT / "tests"))
        sys.path.insert(0, str(ROOT / "tools"))
        from model_error import calibration

        cal = calibration(config, args.hidden_sensor, args.noise_counts)[1]
        args.no_figure = True
    print("| force model | s_c / L | \\|F\\| [N] | σ(s_c) one frame [mm] | σ(s_c) 50 ms [mm] | σ(F) known s_c [mN] "
          "| σ(F) unknown s_c [mN] |")
    print("|---|---|---|---|---|---|---|")
    for constraint, fr, f, one, window, known, unknown in table(config, p, args.noise_counts, cal):
        print(f"| {constraint} | {fr:g} | {f:g} | {one:.1f} | {window:.2f} | {known:.1f} | {unknown:.1f} |")
    if not args.no_figure:
        figure(config, p, args.noise_counts, args.out)
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
