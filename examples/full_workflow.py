"""The whole bendsense workflow from Python, on the virtual sensor (no hardware).

Run it as a script::

    python examples/full_workflow.py --out figures

or cell by cell (``# %%``) in an editor with notebook cells (VS Code, Spyder, Jupyter
via jupytext). It simulates the calibration strips and a time-varying session of the
paper's prototype, calibrates the sensor, reconstructs the shape of every frame,
estimates the tip force with its uncertainty, compares everything with the simulated
truth, and saves figures and results into ``--out`` (default: a new temporary
directory). Runs in well under a minute.
"""

# %% Set-up
import argparse
import tempfile
import time
from pathlib import Path

import matplotlib

if __name__ == "__main__" and matplotlib.get_backend().lower() not in ("agg", "pdf", "svg"):
    # a script writes files; a notebook keeps its inline backend
    matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import bendsense
from bendsense import plots
from bendsense.results import read_results, write_results
from bendsense.sim.actuator import SimulatedActuator
from bendsense.sim.scenarios import CALIBRATION_RADII_M, time_varying_profile
from bendsense.sim.sensor import VirtualSensor, calibration_shifts

parser = argparse.ArgumentParser(description=(__doc__ or "").strip().split("\n")[0])
parser.add_argument("--out", type=Path, default=None, help="output directory (default: a new temporary one)")
parser.add_argument("--seconds", type=float, default=5.0, help="length of the simulated session [s]")
args, _ = parser.parse_known_args()  # parse_known_args: tolerate a notebook kernel's own arguments
out = args.out if args.out is not None else Path(tempfile.mkdtemp(prefix="bendsense-example-"))
out.mkdir(parents=True, exist_ok=True)
started = time.perf_counter()

# %% The configuration and the virtual sensor
# The paper's prototype: a 134 mm actuator with a 16-segment inductive curvature sensor.
config = bendsense.load_config()
sensor = VirtualSensor.from_config(config, noise_counts=1.5, seed=0)
print(f"sensor: {config.sensor.n_segments} segments, {config.sensor.length_m * 1e3:.0f} mm, "
      f"{sensor.adc_bits}-bit ADC, noise {sensor.noise_counts} counts")

# %% Calibration strips
# The sensor pressed onto arcs of radius R gives the shifts S_i = d L_i / R (paper
# section V-B); the flat sensor gives the offsets A0 (eq. 1). 50 frames per recording.
rng = np.random.default_rng(1)
n = config.sensor.n_segments
flat = sensor.measure(np.zeros((50, n)), rng=rng).counts
strips = [
    sensor.measure(np.broadcast_to(calibration_shifts(config.sensor, r), (50, n)), rng=rng).counts
    for r in CALIBRATION_RADII_M
]

# %% Calibrate (paper eq. 2), choosing the degree by cross-validation
cal = bendsense.Calibration.from_data(flat, strips, CALIBRATION_RADII_M, config.sensor, degree="auto")
print(cal.report())
cal.save(out / "calibration.yaml")
axes = cal.plot()
axes[0].set_title(f"calibration, degree {cal.degree}")
axes[0].figure.savefig(out / "calibration.png", dpi=120)

# %% A time-varying session
# Pressure ramps between 0 and 100 kPa while a 0.15 N contact force, normal to the tip
# and pushing against the bending (paper eq. 21), switches on and off.
rate_hz = 50.0
t_s = np.arange(round(args.seconds * rate_hz)) / rate_hz
pressure_pa, contact_n = time_varying_profile(t_s)
actuator = SimulatedActuator.from_config(config, sensor=sensor)
truth = actuator.frames(pressure_pa, contact_n=contact_n, time_series=True, rng=rng)
session = bendsense.Session(
    t_s=t_s,
    signals=truth.counts,
    pressure_pa=pressure_pa,
    extra={"true_fx_n": truth.force_n[:, 0], "true_fy_n": truth.force_n[:, 1]},
)
print(f"session: {len(t_s)} frames at {rate_hz:g} Hz, {truth.n_invalid} without a valid true shape")

# %% Reconstruct the shape of every frame (paper eq. 1-7)
shape = bendsense.reconstruct(session.signals, cal, config.sensor, s_m=truth.s_m)
shape_error = np.linalg.norm(shape.positions_m - truth.positions_m, axis=-1).max(axis=-1)
print(f"shape: max position error {shape_error.max() * 1e3:.2f} mm "
      f"({shape_error.max() / config.sensor.length_m * 100:.2f} % of the length, paper eq. 20)")

# %% Estimate the tip force with its uncertainty (paper eq. 18, 21)
# 'normal': the force is normal to the tip tangent, one unknown per frame. Passing the
# calibration propagates the sensor noise to the standard deviation std_n.
force = bendsense.estimate_force(shape, session.pressure_pa, config, constraint="normal", calibration=cal)
free = bendsense.estimate_force(shape, session.pressure_pa, config, constraint="none", calibration=cal, max_iter=25)
print(f"force: {force.wall_time_s * 1e3 / len(t_s):.2f} ms per frame (normal; a process's first estimate loads the "
      f"compiled kernels), {free.wall_time_s * 1e3 / len(t_s):.2f} ms per frame (none)")

# %% Compare with the simulated truth
# Frames where the shape cannot tell a force component (an axial load on the nearly
# straight actuator at low pressure, without a constraint) report an infinite σ along
# it; they are counted apart instead of entering the error.
valid = truth.valid
for name, est in (("normal", force), ("none", free)):
    determined = np.all(np.isfinite(est.std_n), axis=-1)
    ok = valid & est.success & determined
    err = est.force_n[ok] - truth.force_n[ok]
    within = np.abs(err) <= 2 * est.std_n[ok]
    size = np.linalg.norm(err, axis=-1)
    print(f"  constraint {name:6s}: |error| median {np.median(size):.4f} N, RMS {np.sqrt(np.mean(size**2)):.4f} N "
          f"over {ok.sum()} frames, truth within ±2σ {within.mean():.0%}; {np.count_nonzero(~est.success)} not "
          f"converged, {np.count_nonzero(est.success & ~determined)} with a component the shape does not determine")
print("  (σ: sensor noise, calibration error and the config's parameter prior on K0(P) and EI(P), scaled up where "
      "the shape misfits the model; not the constraint's error)")

# %% Figures: shapes against the truth, force against the truth
frames = np.linspace(0, len(t_s) - 1, 6).astype(int)
fig, ax = plt.subplots(figsize=(5, 5), layout="constrained")
plots.plot_shape_comparison(shape.positions_m[frames], truth.positions_m[frames, ::12], ax=ax,
                            labels=[f"t = {t_s[k]:.1f} s" for k in frames])
ax.set_title("reconstructed (solid) and true (dotted) shapes")
fig.savefig(out / "shapes.png", dpi=120)

fig, axs = plt.subplots(2, 1, sharex=True, figsize=(8, 5), layout="constrained")
for i, (ax, comp) in enumerate(zip(axs, ("F_x", "F_y"))):
    ax.plot(t_s, truth.force_n[:, i], "k:", label="truth")
    ax.plot(t_s, force.force_n[:, i], color="C0", label="estimate (normal)")
    ax.fill_between(t_s, force.force_n[:, i] - 2 * force.std_n[:, i], force.force_n[:, i] + 2 * force.std_n[:, i],
                    color="C0", alpha=0.25, linewidth=0, label="±2σ")
    ax.set_ylabel(f"${comp}$ [N]")
axs[0].legend(fontsize="small", ncols=3)
axs[1].set_xlabel("t [s]")
fig.savefig(out / "force.png", dpi=120)

# %% Save the results as the command line does, and its summary figure
write_results(out / "results", session, shape, force, overwrite=True)
results = read_results(out / "results")
fig = plots.plot_results(results, out / "summary.png")
print(f"results: {len(results['t_s'])} frames, columns {', '.join(list(results.columns)[:3])}, ...")
print(f"wrote {', '.join(sorted(p.name for p in out.iterdir()))} to {out} "
      f"in {time.perf_counter() - started:.1f} s")
