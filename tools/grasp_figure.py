"""The figure of a grasp held with force feedback (docs/grasping.md): a control session beside the simulator's truth.

Run from the repository root, on a session written by ``bendsense control ... -o SESSION``
and the truth file of the simulated board (``sim-device --truth TRUTH.csv``)::

    python tools/grasp_figure.py SESSION TRUTH.csv [--out docs/img/grasping.png] [--config GRIPPER.yaml]

Three panels: (a) each pressure line's set-point (as sent) and measured pressure;
(b) each finger's tracked contact normal force N = F · n with its ±2σ band, the target
and the simulator's true contact force; (c) the fingers at the last frame of the hold
(their PCC shapes from ``<finger>/results.csv``), each with its contact point and the
object's push along n. Rows of the session and the truth are matched by the frame's
sequence number. Prints one line per finger: the mean true and estimated force over the
last half second of the hold.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np


def read_csv(path) -> dict:
    """The columns of a CSV file (comment lines before the header skipped), as arrays (numbers where they are)."""
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(line for line in fh if not line.startswith("#")))
    header, body = rows[0], [r for r in rows[1:] if len(r) == len(rows[0])]
    out = {}
    for i, name in enumerate(header):
        values = [r[i] for r in body]
        try:
            out[name] = np.array(values, dtype=float)
        except ValueError:
            out[name] = np.array(values, dtype=object)
    return out


def fingers_of(log: dict) -> list:
    """The controlled fingers of a control log (None: a single actuator, no prefixes)."""
    names = [c[: -len("_normal_force_n")] for c in log if c.endswith("_normal_force_n")]
    return names or [None]


def draw(session: Path, truth_path: Path, out: Path, config=None) -> None:
    """Draw the figure of ``session`` against the truth file to ``out``; ``config`` the one controlled with."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from bendsense.control import contact_normal
    from bendsense.shape.pcc import forward_kinematics

    log, truth = read_csv(session / "control.csv"), read_csv(truth_path)
    row_of = {int(s): i for i, s in enumerate(truth["seq"])}
    idx = np.array([row_of.get(int(s), -1) for s in log["seq"]])
    keep = idx >= 0
    t, idx = log["t_s"][keep], idx[keep]
    fingers = fingers_of(log)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.4), gridspec_kw={"width_ratios": [1.1, 1.1, 0.8]})
    ax_p, ax_f, ax_s = axes
    lines = sorted(int(c[4:].split("_")[0]) for c in log if c.startswith("line") and c.endswith("_setpoint_pa"))
    for k in lines or [None]:
        sp = log["setpoint_pa" if k is None else f"line{k}_setpoint_pa"][keep]
        p = log["pressure_pa" if k is None else f"line{k}_pressure_pa"][keep]
        (h,) = ax_p.plot(t, p / 1e3, lw=1.3, label="pressure" if k is None else f"line {k} pressure")
        ax_p.plot(t, sp / 1e3, "--", lw=1, color=h.get_color(),
                  label="set-point" if k is None else f"line {k} set-point")
    ax_p.set(xlabel="t [s]", ylabel="pressure [kPa]", title="(a) set-points (dashed) and pressures")
    ax_p.legend(fontsize=7, ncol=2)
    end = np.flatnonzero(np.isfinite(log[(f"{fingers[0]}_" if fingers[0] else "") + "normal_force_n"][keep]))[-1]
    hold = t >= t[end] - 0.5
    for i, name in enumerate(fingers):
        p = "" if name is None else f"{name}_"
        force, std = log[f"{p}normal_force_n"][keep], log[f"{p}normal_force_std_n"][keep]
        true = np.hypot(truth[f"{p}fx_n"][idx], truth[f"{p}fy_n"][idx])
        colour = f"C{i}"
        ax_f.fill_between(t, (force - 2 * std) * 1e3, (force + 2 * std) * 1e3, color=colour, alpha=0.15, lw=0)
        ax_f.plot(t, force * 1e3, color=colour, lw=1.3, label=f"{name or 'finger'} tracked N (±2σ)")
        ax_f.plot(t, true * 1e3, ":", color="k" if i == 0 else colour, lw=1.2,
                  label="simulator's truth" if i == 0 else None)
        target = log[f"{p}target_force_n"][keep][-1]
        print(f"{name or 'finger'}: last 0.5 s of the hold, true {np.mean(true[hold]) * 1e3:.1f} mN, "
              f"estimated {np.mean(force[hold]) * 1e3:.1f} mN (target {target * 1e3:g} mN)")
        _finger(ax_s, session, name, i, config, end, log, keep, contact_normal, forward_kinematics)
    ax_f.axhline(log[f"{'' if fingers[0] is None else fingers[0] + '_'}target_force_n"][keep][-1] * 1e3, color="0.5",
                 lw=0.8)
    ax_f.set(xlabel="t [s]", ylabel="contact normal force [mN]", title="(b) tracked force and truth")
    ax_f.legend(fontsize=7)
    ax_s.set(xlabel="x [mm] (fingers side by side)", ylabel="y [mm]",
             title="(c) the hold: contacts, the object's push N n")
    ax_s.set_aspect("equal")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


def _finger(ax, session, name, i, config, end, log, keep, contact_normal, forward_kinematics):
    """One finger's shape at frame ``end`` of the hold, its contact point and the object's push (150 mm per N)."""
    from bendsense import load_config

    results = read_csv(session / ("results.csv" if name is None else f"{name}/results.csv"))
    kappa = np.array([results[f"kappa{j}"][keep][end] for j in range(1, 1 + sum(c.startswith("kappa")
                                                                                   for c in results))])
    cfg = load_config() if config is None else (config.finger(name).config if name else config)
    lengths = cfg.sensor.lengths_m
    s = np.linspace(0.0, float(np.sum(lengths)), 60)
    pos, _ = forward_kinematics(kappa, lengths, s)
    p = "" if name is None else f"{name}_"
    s_c = min(float(log[f"{p}contact_s_m"][keep][end]), float(np.sum(lengths)))
    at, phi = forward_kinematics(kappa, lengths, [s_c])
    x0 = 60.0 * i  # the fingers drawn side by side
    ax.plot(pos[:, 0] * 1e3 + x0, pos[:, 1] * 1e3, color=f"C{i}", lw=2.5, label=name)
    cx, cy = at[0, 0] * 1e3 + x0, at[0, 1] * 1e3
    ax.plot(cx, cy, "o", color="k", ms=4)
    push = float(log[f"{p}normal_force_n"][keep][end]) * contact_normal(phi[0]) * 150.0  # 150 mm per N
    ax.annotate("", xy=(cx, cy), xytext=(cx - push[0], cy - push[1]),
                arrowprops={"arrowstyle": "->", "color": "k", "lw": 1.4})
    if i == 0:
        ax.text(cx - push[0], cy - push[1] - 6, "N n", fontsize=8, ha="center")
    ax.text(x0, -12, name or "", ha="center", fontsize=8)


def main(argv=None):
    """The command line (module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("session", type=Path, help="the control session (bendsense control -o SESSION)")
    ap.add_argument("truth", type=Path, help="the simulated board's truth file (sim-device --truth)")
    ap.add_argument("--out", type=Path, default=Path("grasping.png"), help="the figure (default grasping.png)")
    ap.add_argument("--config", type=Path, help="the config controlled with (default: the session's)")
    args = ap.parse_args(argv)
    config = args.config
    if config is None:
        import yaml

        from bendsense.config import Config, GripperConfig

        meta = yaml.safe_load((args.session / "meta.yaml").read_text(encoding="utf-8"))
        snap = meta.get("config")
        config = None if snap is None else (GripperConfig if "fingers" in snap else Config).from_dict(snap)
    else:
        from bendsense import load_config

        config = load_config(config)
    draw(args.session, args.truth, args.out, config)


if __name__ == "__main__":
    main()
