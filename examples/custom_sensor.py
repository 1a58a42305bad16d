"""A configuration for a different sensor and actuator, built and checked from Python.

Run it as a script::

    python examples/custom_sensor.py --out figures

A config is a set of frozen, keyword-only dataclasses with SI units in the field names
(``bendsense.config``); they check their values when built and name the bad field. This
script describes a 10-segment sensor on a shorter actuator, saves it as YAML (the file
``bendsense ... --config`` reads), simulates that sensor's calibration strips and a
tip-load experiment, calibrates, estimates the vertical tip loads and compares them with
the simulated truth.
"""

# %% Set-up
import argparse
import tempfile
from pathlib import Path

import matplotlib

if __name__ == "__main__" and matplotlib.get_backend().lower() not in ("agg", "pdf", "svg"):
    matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import bendsense
from bendsense.config import (
    ActuatorConfig,
    Config,
    EstimationConfig,
    GravityConfig,
    MaterialConfig,
    SensorConfig,
    StiffnessConfig,
    save_config,
)
from bendsense.plots import plot_shapes
from bendsense.sim.scenarios import simulate

parser = argparse.ArgumentParser(description=(__doc__ or "").strip().split("\n")[0])
parser.add_argument("--out", type=Path, default=None, help="output directory (default: a new temporary one)")
args, _ = parser.parse_known_args()
out = args.out if args.out is not None else Path(tempfile.mkdtemp(prefix="bendsense-example-"))
out.mkdir(parents=True, exist_ok=True)

# %% Describe the sensor: 10 coils, 12 mm apart, strips 1.5 mm apart
sensor = SensorConfig(
    n_segments=10,
    segment_lengths_m=[0.012] * 10,  # l_i, base to tip [m]
    strip_gap_m=0.0015,  # d [m]
    sleeve_thickness_m=0.001,  # c [m]
    calibration_adds_sleeve=False,  # κ_cal = 1/R: the strip radius is measured at the sensor
    coil_diameter_m=0.008,  # coil geometry: used by the simulator only
    coil_turns=20,
    coil_pitch_m=0.012,
)

# Mistakes are caught when the config is built, with the field named:
try:
    SensorConfig(n_segments=10, segment_lengths_m=[0.012] * 9, strip_gap_m=0.0015, sleeve_thickness_m=0.001)
except bendsense.ConfigError as err:
    print(f"ConfigError: {err}")

# %% The actuator: a shorter, stiffer one, hanging (gravity along +y, the tip below the base)
config = Config(
    name="10-coil sensor on a 125 mm actuator",
    sensor=sensor,
    actuator=ActuatorConfig(
        chamber_radius_m=0.006, bottom_thickness_m=0.0025, wall_thickness_m=0.002, length_m=0.125, mass_kg=0.032
    ),
    # free-bending parameters: identify them with `bendsense identify free-bending`
    material=MaterialConfig(shear_modulus_pa=2.2e5, sensor_stiffness_nm_per_rad=1.5e-3, prebend_angle_rad=0.0),
    stiffness=StiffnessConfig(ei0_nm2=3.0e-3, ei1_nm2_per_pa=1.5e-8),  # EI(P) = ei0 + ei1 P (paper eq. 15)
    gravity=GravityConfig(g_m_per_s2=9.81, direction=(0.0, 1.0)),
    estimation=EstimationConfig(constraint="vertical", n_points=41),
)
print(f"{config.name}: sensor {config.sensor.length_m * 1e3:.0f} mm, weight {config.weight_per_length_n_per_m} N/m, "
      f"EI(60 kPa) = {config.stiffness.ei_nm2(60e3):.5f} N m^2")

# %% Save it as YAML and read it back (what `--config` on the command line reads)
save_config(config, out / "my_sensor.yaml")
assert bendsense.load_config(out / "my_sensor.yaml") == config
print((out / "my_sensor.yaml").read_text()[:400], "...")

# %% Simulate the calibration strips of this sensor, and calibrate
cal_dir = simulate("calibration", out / "sim-calibration", config, seed=3, overwrite=True,
                   radii_m=(0.04, 0.05, 0.06, 0.08, 0.1, 0.15, 0.2, 0.4), frames_per_strip=30)
cal = bendsense.Calibration.fit(cal_dir / "manifest.yaml", config.sensor, degree="auto")
print(cal.report())
cal.save(out / "my_calibration.yaml")

# %% A tip-load experiment on the hanging actuator, and the estimate of its vertical loads
# The scenario's loads are F = (0, -load) in the base frame: toward the base, which on
# this hanging actuator is a push upward against gravity.
loads_dir = simulate("tip-loads", out / "sim-tip-loads", config, seed=3, overwrite=True,
                     pressures_pa=(40e3, 80e3, 120e3), loads_n=(0.0, 0.1, 0.2), frames_per_config=4)
session = bendsense.read_session(loads_dir / "tip_loads.csv")
shape = bendsense.reconstruct(session.signals, cal, config.sensor)
force = bendsense.estimate_force(shape, session.pressure_pa, config, constraint="vertical", calibration=cal)

true_fy = session.extra["fy_n"] + 0.0  # + 0.0 turns -0.0 into 0.0 for printing
print(f"{'P [kPa]':>8} {'true Fy [N]':>12} {'estimate [N]':>13} {'std [N]':>8}")
for p in np.unique(session.pressure_pa):
    for f in np.unique(true_fy):
        rows = (session.pressure_pa == p) & (true_fy == f)
        print(f"{p / 1e3:8.0f} {f:12.3f} {force.force_n[rows, 1].mean():13.4f} {force.std_n[rows, 1].mean():8.4f}")
ok = force.success
print(f"RMS error of Fy: {np.sqrt(np.mean((force.force_n[ok, 1] - true_fy[ok]) ** 2)):.4f} N "
      f"over {ok.sum()} of {ok.size} frames")

# %% Plot the reconstructed shapes of the first frame of every configuration
fig, ax = plt.subplots(figsize=(5, 5), layout="constrained")
first = np.flatnonzero(np.r_[True, np.diff(session.pressure_pa) != 0] | np.r_[True, np.diff(true_fy) != 0])
labels = [f"{session.pressure_pa[k] / 1e3:.0f} kPa, Fy = {true_fy[k]:+.1f} N" for k in first]
plot_shapes(shape, ax, frames=first, labels=labels)
ax.set_title("hanging 10-coil actuator under vertical tip loads", fontsize="medium")
fig.savefig(out / "custom_sensor_shapes.png", dpi=120)
print(f"wrote {out / 'custom_sensor_shapes.png'}")
