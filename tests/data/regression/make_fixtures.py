"""Write the estimator's regression fixtures (tests/integration/test_regression.py checks them).

The fixtures freeze the outputs (force, σ, success, message, residual, χ²/dof) of the
force estimator on small corpora: cold independent frames (random pressures 15–120 kPa,
loads up to 0.25 N in any direction, shuffled), a smooth series (batched and frame by
frame with ``initial=``), every constraint, the simulator's time-varying and tip-load
sessions, the residual fallback and a shape given by points. Inputs (curvatures,
pressures, the calibration) are stored beside the outputs, so that the check does not
depend on the simulators.

    python tests/data/regression/make_fixtures.py      # rewrites tests/data/regression/*.npz
"""

import json
import pathlib
import tempfile

import numpy as np

import bendsense
from bendsense.calibration import Calibration
from bendsense.estimation import constraint_basis, estimate_force
from bendsense.mechanics.actuator import FreeBendingModel
from bendsense.mechanics.beam import solve_beam
from bendsense.shape.pcc import reconstruct, shifts_to_curvatures
from bendsense.sim.scenarios import simulate
from bendsense.sim.sensor import shifts_from_shape

HERE = pathlib.Path(__file__).parent
# frozen with the paper config of the time, which declared no parameter_covariance (issue 22 gave the
# shipped config a prior, which widens σ and changes χ²): the estimator is compared on that config
CFG = bendsense.load_config().replace(parameter_covariance=None)
MODEL = FreeBendingModel.from_config(CFG)
L = CFG.actuator.length_m
SENSOR = CFG.sensor
S_DENSE = np.linspace(0.0, L, 135)


def beam(pressure_pa, force_n, s_m=S_DENSE):
    return solve_beam(L, CFG.stiffness.ei_nm2(pressure_pa), MODEL.tip_curvature_per_m(pressure_pa), force_n,
                      CFG.weight_per_length_n_per_m, 0.0, s_m, warn=False)


def curvatures(sol, rng, noise_m):
    shifts = shifts_from_shape(sol.s_m, sol.angle_rad, SENSOR.lengths_m, SENSOR.strip_gap_m)
    shifts = shifts + noise_m * rng.standard_normal(shifts.shape)
    return shifts_to_curvatures(shifts, SENSOR.lengths_m, SENSOR.strip_gap_m)


def cold_frames(n, constraint, rng, noise_m=2e-6, **kw):
    """Independent frames: pressure U(15, 120) kPa, load up to 0.25 N (in the constraint's span)."""
    p = rng.uniform(15e3, 120e3, n)
    if constraint == "none":
        a = rng.uniform(0.0, 2.0 * np.pi, n)
        r = 0.25 * np.sqrt(rng.uniform(0.0, 1.0, n))
        force = np.stack([r * np.cos(a), r * np.sin(a)], axis=-1)
    else:
        phi = MODEL.tip_angle_rad(p)
        d, _ = constraint_basis(constraint, phi, **kw)
        force = d[..., 0] * rng.uniform(-0.25, 0.25, n)[:, None]
    order = rng.permutation(n)
    sol = beam(p[order], force[order])
    return curvatures(sol, rng, noise_m), p[order]


def smooth_series(n, rng, rate_hz=100.0):
    t = np.arange(n) / rate_hz
    p = 70e3 + 50e3 * np.sin(2 * np.pi * 0.13 * t)
    force = np.stack([0.2 * np.sin(2 * np.pi * 0.31 * t), 0.15 * np.cos(2 * np.pi * 0.17 * t)], -1)
    return curvatures(beam(p, force), rng, 1e-6), p


def outputs(est):
    return {"force_n": np.asarray(est.force_n), "std_n": np.asarray(est.std_n),
            "success": np.asarray(est.success), "message": np.asarray(est.message).astype(str),
            "residual_m": np.asarray(est.residual_m), "chi2_per_dof": np.asarray(est.chi2_per_dof),
            "p_value": np.asarray(est.p_value)}  # (not in the frozen fixtures: newer than them)


def run_case(inputs, mode, options, cal):
    """The estimator on one case (the test repeats exactly this)."""
    kw = {"objective": "positions", **options}  # frozen from the position objective (paper eq. 18)
    if kw.pop("with_calibration", False):
        kw["calibration"] = cal
    shape = inputs["shape"]
    if "s_m" in inputs:
        kw["s_m"] = inputs["s_m"]
    P = inputs["pressure_pa"]
    if mode == "batch":
        return outputs(estimate_force(shape, P, CFG, **kw))
    rows, prev = [], None
    for i in range(len(P)):
        if mode == "warm" and prev is not None:
            kw["initial"] = prev
        prev = estimate_force(shape[i], P[i], CFG, **kw)
        rows.append(outputs(prev))
    return {key: np.stack([r[key] for r in rows]) for key in rows[0]}


def cases(cal, sessions, rng):
    kap, p = cold_frames(160, "none", rng)
    yield "cold_batch", {"shape": kap, "pressure_pa": p}, "batch", {"with_calibration": True}
    yield "cold_single", {"shape": kap[:40], "pressure_pa": p[:40]}, "single", {"with_calibration": True}
    kap, p = smooth_series(60, rng)
    yield "smooth_batch", {"shape": kap, "pressure_pa": p}, "batch", {"with_calibration": True}
    yield "smooth_warm", {"shape": kap[:30], "pressure_pa": p[:30]}, "warm", {"with_calibration": True}
    for name, constraint, opts in [
        ("vertical", "vertical", {}), ("horizontal", "horizontal", {}),
        ("direction", "direction", {"direction": [0.6, -0.8]}), ("normal", "normal", {}),
        ("normal_shape", "normal", {"tip_angle_source": "shape"}),
        ("follower", "follower", {"follower_angle_rad": 1.2}),
        ("normal_push", "normal", {"push_only": True}),
    ]:
        kw = {k: v for k, v in opts.items() if k in ("direction",)}
        kap, p = cold_frames(12, constraint if constraint != "follower" else "none", rng, **kw)
        options = {"constraint": constraint, "with_calibration": True, **opts}
        yield f"constraint_{name}", {"shape": kap, "pressure_pa": p}, "batch", options
        yield f"constraint_{name}_single", {"shape": kap[:4], "pressure_pa": p[:4]}, "single", options
    tv, tl = sessions
    kap = reconstruct(tv.signals[::20], cal, SENSOR).curvature_per_m
    yield "session_time_varying", {"shape": kap, "pressure_pa": tv.pressure_pa[::20]}, "batch", {
        "constraint": "normal", "with_calibration": True}
    kap = reconstruct(tl.signals[::5], cal, SENSOR).curvature_per_m
    yield "session_tip_loads", {"shape": kap, "pressure_pa": tl.pressure_pa[::5]}, "batch", {"with_calibration": True}
    kap, p = cold_frames(10, "none", rng)
    yield "residual_fallback", {"shape": kap, "pressure_pa": p}, "batch", {"noise_std": 0.0}
    kap, p = cold_frames(6, "none", rng, noise_m=0.0)
    yield "exact_beam_curvatures", {"shape": kap, "pressure_pa": p}, "batch", {"with_calibration": True}
    p = np.array([20e3, 60e3, 110e3])
    sol = beam(p, np.array([[0.05, -0.1], [-0.1, 0.05], [0.2, 0.1]]))
    yield "points", {"shape": sol.positions_m, "s_m": sol.s_m, "pressure_pa": p}, "batch", {}
    yield "points_single", {"shape": sol.positions_m, "s_m": sol.s_m, "pressure_pa": p}, "single", {}


def main():
    rng = np.random.default_rng(20261123)
    with tempfile.TemporaryDirectory() as tmp:
        root = pathlib.Path(tmp)
        for name, sub in (("calibration", "cal"), ("time-varying", "tv"), ("tip-loads", "tl")):
            simulate(name, root / sub, seed=0)
        cal = Calibration.fit(root / "cal" / "manifest.yaml")
        sessions = (bendsense.read_session(root / "tv" / "session.csv"),
                    bendsense.read_session(root / "tl" / "tip_loads.csv"))
    cal_path = HERE / "calibration.yaml"
    cal.save(cal_path)
    cal = Calibration.load(cal_path)  # as the test will see it
    for old in HERE.glob("*.npz"):
        old.unlink()
    total = 0
    for name, inputs, mode, options in cases(cal, sessions, rng):
        out = run_case(inputs, mode, options, cal)
        total += len(inputs["pressure_pa"])
        np.savez_compressed(HERE / f"{name}.npz", mode=mode, options=json.dumps(options),
                            **{f"in_{k}": v for k, v in inputs.items()}, **{f"out_{k}": v for k, v in out.items()})
        ok = out["success"].mean()
        print(f"{name:32s} {len(inputs['pressure_pa']):4d} frames  {mode:6s}  success {ok:.0%}")
    print(f"{total} frames")


if __name__ == "__main__":
    main()
