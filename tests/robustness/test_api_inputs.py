"""The public API with the obvious wrong inputs: the library's own errors, naming the argument.

Each case calls a public function (``bendsense.__all__``, and ``bendsense.pipeline.process``)
with a wrong shape, a wrong type, a path where an object is expected, None, an empty
array or NaN, and checks that it raises a :class:`~bendsense.errors.BendsenseError`
whose message names the argument (never numpy's broadcast ``ValueError``, an
``AttributeError`` or a ``TypeError`` from deep inside). Where a path is the obvious
alternative to an object, it is accepted.
"""

import numpy as np
import pytest

import bendsense
from bendsense import plots
from bendsense.calibration import Calibration
from bendsense.errors import ArgumentError, BendsenseError, ConfigError, SessionError
from bendsense.identify import fit_free_bending
from bendsense.mechanics.actuator import FreeBendingModel
from bendsense.pipeline import process
from robustness.test_invalid_corpus import GOOD_CAL, GOOD_CSV

N = 16
CONFIG = bendsense.load_config()
CAL = Calibration.load(GOOD_CAL)
SESSION = bendsense.read_session_csv(GOOD_CSV)
SIGNALS = SESSION.signals
SHAPE = bendsense.reconstruct(SIGNALS, CAL, CONFIG)
KAPPA = SHAPE.curvature_per_m

CASES = {
    # Session(t_s, signals, pressure_pa): the case, mismatched lengths
    "session_pressure_length": (lambda: bendsense.Session(np.arange(4.0), np.zeros((4, N)), np.zeros(5)),
                                SessionError, r"pressure_pa: expected one number or shape \(4,\)"),
    "session_signals_length": (lambda: bendsense.Session(np.arange(4.0), np.zeros((3, N)), 0.0),
                               SessionError, r"signals: expected shape \(4, N\)"),
    "session_t_text": (lambda: bendsense.Session("x", np.zeros((1, N)), 0.0), SessionError, r"t_s: expected numbers"),
    "session_signals_dict": (lambda: bendsense.Session(np.arange(2.0), {"a": 1}, 0.0), SessionError,
                             r"signals: expected numbers"),
    "session_pressure_path": (lambda: bendsense.Session(np.arange(2.0), np.zeros((2, N)), str(GOOD_CSV)),
                              SessionError, r"pressure_pa: expected numbers"),
    "session_pressure_2d": (lambda: bendsense.Session(np.arange(4.0), np.zeros((4, N)), np.zeros((4, 4))),
                            SessionError,
                            r"pressure_pa: expected one number or shape \(4,\) \(frames of t_s\), got shape \(4, 4\)"),
    "session_seq_text": (lambda: bendsense.Session(np.arange(2.0), np.zeros((2, N)), 0.0, seq=["a", "b"]),
                         SessionError, r"seq: expected integers"),
    # readers and writers: a path, not None or a number
    "read_session_none": (lambda: bendsense.read_session(None), ArgumentError,
                          r"path: expected a file path \(str or os\.PathLike\), got None"),
    "read_session_array": (lambda: bendsense.read_session(np.zeros(3)), ArgumentError,
                           r"path: expected a file path .*, got an array of shape \(3,\)"),
    "read_session_csv_int": (lambda: bendsense.read_session_csv(3), ArgumentError, r"path: expected a file path"),
    "read_session_nul": (lambda: bendsense.read_session("a\x00b.csv"), ArgumentError, r"path: expected a file path"),
    "write_session_not_a_session": (lambda: bendsense.session.write_session_csv(SIGNALS, "out.csv"), ArgumentError,
                                    r"session: expected a Session \(bendsense\.read_session\(path\)\), got an array"),
    "write_session_path_none": (lambda: bendsense.session.write_session_csv(SESSION, None), ArgumentError,
                                r"path: expected a file path"),
    "load_config_number": (lambda: bendsense.load_config(3), ConfigError, r"path: expected a file path"),
    "save_config_not_a_config": (lambda: bendsense.config.save_config({"a": 1}, "c.yaml"), ArgumentError,
                                 r"config: expected a Config \(bendsense\.load_config\(path\)\), got dict"),
    "calibration_load_none": (lambda: Calibration.load(None), ConfigError, r"path: expected a file path"),
    "calibration_fit_none": (lambda: Calibration.fit(None), ArgumentError, r"manifest_path: expected a file path"),
    "calibration_save_number": (lambda: CAL.save(3.5), ArgumentError, r"path: expected a file path"),
    # reconstruct
    "reconstruct_sensor_path": (lambda: bendsense.reconstruct(SIGNALS, CAL, "paper.yaml"), ArgumentError,
                                r"sensor: expected a SensorConfig or a Config .*, got str"),
    "reconstruct_s_m_text": (lambda: bendsense.reconstruct(SIGNALS, CAL, CONFIG.sensor, s_m=["a"]), ArgumentError,
                             r"s_m: expected numbers"),
    "reconstruct_channels": (lambda: bendsense.reconstruct(np.zeros((3, 5)), CAL, CONFIG.sensor), ArgumentError,
                             r"signals: expected 16 channels on the last axis, got shape \(3, 5\)"),
    "reconstruct_calibration_path": (lambda: bendsense.reconstruct(SIGNALS, str(GOOD_CAL), CONFIG), ArgumentError,
                                     r"calibration: expected a Calibration"),
    # solve_beam
    "solve_beam_method_array": (lambda: bendsense.solve_beam(0.1, 2.5e-3, 10.0, method=np.zeros(2)), ArgumentError,
                                r"method: must be one of fast, shooting, paper"),
    "solve_beam_length_nan": (lambda: bendsense.solve_beam(np.nan, 2.5e-3, 10.0), ArgumentError, r"length_m"),
    "solve_beam_s_m_empty": (lambda: bendsense.solve_beam(0.1, 2.5e-3, 10.0, s_m=np.array([])), ArgumentError,
                             r"s_m: expected a non-empty 1-D array"),
    # estimate_force
    "estimate_no_frames": (lambda: bendsense.estimate_force(np.zeros((0, N)), 5e4, CONFIG), ArgumentError,
                           r"shape: no frames to estimate \(batch shape \(0,\)\)"),
    "estimate_constraint_array": (lambda: bendsense.estimate_force(np.zeros(N), 5e4, CONFIG, constraint=np.zeros(2)),
                                  ArgumentError, r"constraint: must be one of"),
    "estimate_method_list": (lambda: bendsense.estimate_force(np.zeros(N), 5e4, CONFIG, method=["fast"]),
                             ArgumentError, r"method: must be one of"),
    "estimate_config_path": (lambda: bendsense.estimate_force(np.zeros(N), 5e4, "paper.yaml"), ArgumentError,
                             r"config: expected a Config"),
    "estimate_pressure_nan": (lambda: bendsense.estimate_force(np.zeros(N), np.nan, CONFIG), ArgumentError,
                              r"pressure_pa: must be finite"),
    "estimate_objective_array": (lambda: bendsense.estimate_force(np.zeros(N), 5e4, CONFIG, objective=np.zeros(2)),
                                 ArgumentError, r"objective: must be one of angles, positions"),
    "estimate_angle_source_array": (
        lambda: bendsense.estimate_force(np.zeros(N), 5e4, CONFIG, constraint="normal", tip_angle_source=[1]),
        ArgumentError, r"tip_angle_source: must be one of"),
    "estimate_n_points_text": (lambda: bendsense.estimate_force(np.zeros(N), 5e4, CONFIG, n_points="many"),
                               ArgumentError, r"n_points: must be between 3 and 1000 \(an integer\), got 'many'"),
    "estimate_max_iter_text": (lambda: bendsense.estimate_force(np.zeros(N), 5e4, CONFIG, max_iter="x"),
                               ArgumentError, r"max_iter: must be >= 0 \(an integer\)"),
    "estimate_direction_text": (
        lambda: bendsense.estimate_force(np.zeros(N), 5e4, CONFIG, constraint="direction", direction="down"),
        ArgumentError, r"direction: expected numbers, got \('down',\)"),
    "estimate_noise_std_text": (lambda: bendsense.estimate_force(np.zeros(N), 5e4, CONFIG, noise_std="x"),
                                ArgumentError, r"noise_std: expected numbers"),
    "reconstruct_base_angle_shape": (
        lambda: bendsense.reconstruct(SIGNALS, CAL, CONFIG, base_angle_rad=np.zeros(7)), ArgumentError,
        r"base_angle_rad: shape \(7,\) does not broadcast against the frames \(4,\)"),
    "calibration_fit_sensor_path": (lambda: Calibration.fit("m.yaml", sensor="paper.yaml"), ArgumentError,
                                    r"sensor: expected a SensorConfig or a Config"),
    "session_with_pressure_text": (lambda: SESSION.with_pressure("50 kPa"), SessionError,
                                   r"pressure_pa: expected a number, got '50 kPa'"),
    "session_select_text": (lambda: SESSION.select("all"), SessionError,
                            r"index: expected a slice, a boolean mask of 4 frames or frame numbers below 4, got 'all'"),
    # FreeBendingModel
    "free_bending_from_path": (lambda: FreeBendingModel.from_config("paper.yaml"), ArgumentError,
                               r"config: expected a Config"),
    "free_bending_pressure_text": (
        lambda: FreeBendingModel.from_config(CONFIG).bending_angle_rad("20 kPa"), ArgumentError,
        r"expected numbers, got '20 kPa'"),
    # pipeline.process: the case (a path) is accepted; other wrong types are named
    "process_session_none": (lambda: process(None, CONFIG, CAL), ArgumentError,
                             r"session: expected a Session \(bendsense\.read_session\(path\), or the path\), got None"),
    "process_session_array": (lambda: process(SIGNALS, CONFIG, CAL), ArgumentError,
                              r"session: expected a Session .*, got an array of shape \(4, 16\)"),
    "process_config_dict": (lambda: process(SESSION, {"sensor": 1}, CAL), ArgumentError,
                            r"config: expected a Config .*, got dict"),
    "process_calibration_none": (lambda: process(SESSION, CONFIG, None), ArgumentError,
                                 r"calibration: expected a Calibration"),
    "process_pressure_text": (lambda: process(SESSION, CONFIG, CAL, pressure_pa="x"), ArgumentError,
                              r"pressure_pa: expected a number, got 'x'"),
    "process_pressure_nan": (lambda: process(SESSION, CONFIG, CAL, pressure_pa=np.nan), ArgumentError,
                             r"pressure_pa: expected a finite number"),
    "process_missing_file": (lambda: process("nothere.csv", CONFIG, CAL), SessionError,
                             r"nothere\.csv: no such file or session directory"),
    "process_time_backwards": (
        lambda: process(bendsense.Session([0.0, 0.2, 0.1], SIGNALS[:3], 5e4), CONFIG, CAL, estimate=False),
        ArgumentError, r"frame 2, column t_s: time runs backwards \(0\.1 s after 0\.2 s on frame 1\)"),
    # a campaign on the API (2026-12-01): each of these was numpy's, Python's or an attribute's error from inside
    "estimate_noise_std_length": (lambda: bendsense.estimate_force(KAPPA[:2], 5e4, CONFIG, noise_std=np.ones(3)),
                                  ArgumentError, r"noise_std: shape \(3,\) does not broadcast against the "
                                                 r"channels \(16,\)"),
    "estimate_initial_batch": (lambda: bendsense.estimate_force(KAPPA[:2], 5e4, CONFIG, noise_std=0.02,
                                                                initial=bendsense.estimate_force(
                                                                    KAPPA, 5e4, CONFIG, noise_std=0.02)),
                               ArgumentError, r"initial: shape \(4,\) does not broadcast against the frames "
                                              r"\(2,\)"),
    "estimate_contact_config_calibration": (
        lambda: bendsense.estimate_contact(KAPPA, 5e4, CAL, t_s=np.arange(4.0)), ArgumentError,
        r"config: expected a Config"),
    "fit_free_bending_config_calibration": (
        lambda: fit_free_bending([1e4, 2e4, 3e4, 4e4], [0.1, 0.2, 0.3, 0.4], CAL),
        ArgumentError, r"config: expected a Config"),
    "fit_free_bending_text": (lambda: fit_free_bending("a", "b", CONFIG), ArgumentError,
                              r"pressure_pa: expected numbers"),
    "process_unknown_option": (lambda: process(SESSION, CONFIG, CAL, bogus=1), ArgumentError,
                               r"bogus: not an option of process"),
    "process_shape_text": (lambda: process(SESSION, CONFIG, CAL, shape="x"), ArgumentError,
                           r"shape: expected a Shape"),
    "process_points_zero": (lambda: process(SESSION, CONFIG, CAL, points=0), ArgumentError, r"points: "),
    "reconstruct_base_angle_inf": (lambda: bendsense.reconstruct(SIGNALS, CAL, CONFIG, base_angle_rad=np.inf),
                                   ArgumentError, r"base_angle_rad: must be finite, got inf"),
    "reconstruct_complex": (lambda: bendsense.reconstruct(SIGNALS + 1j, CAL, CONFIG), ArgumentError,
                            r"signals: expected real numbers, got \[2012\.5\+1\.j"),
    "estimate_complex": (lambda: bendsense.estimate_force(KAPPA[0].astype(complex), 5e4, CONFIG), ArgumentError,
                         r"expected real numbers"),
    "session_complex": (lambda: bendsense.Session(np.arange(2.0), np.zeros((2, N), complex), 0.0), SessionError,
                        r"signals: expected real numbers"),
    "check_windows_ms": (lambda: bendsense.check_windows(
        bendsense.estimate_force(KAPPA, SESSION.pressure_pa, CONFIG, noise_std=1.0), SESSION.t_s, window_s=50),
        ArgumentError, r"window_s: 50 s looks like milliseconds \(a window holds one load"),
    "tracker_window_ms": (lambda: bendsense.tracking.Tracker(window_s=50.0), ArgumentError,
                          r"window_s: 50 s looks like milliseconds"),
    # flags: True or False, not text that reads the other way ("no" is true)
    "estimate_strict_text": (lambda: bendsense.estimate_force(KAPPA[0], 5e4, CONFIG, strict="yes"), ArgumentError,
                             r"strict: expected true or false, got 'yes'"),
    "estimate_warm_start_text": (lambda: bendsense.estimate_force(KAPPA, 5e4, CONFIG, warm_start="no"),
                                 ArgumentError, r"warm_start: expected true or false, got 'no'"),
    "process_estimate_text": (lambda: process(SESSION, CONFIG, CAL, estimate="no"), ArgumentError,
                              r"estimate: expected true or false, got 'no'"),
    # plots: the argument named, before a figure is made
    "plot_shapes_frame_beyond": (lambda: plots.plot_shapes(SHAPE, frames=[1000]), ArgumentError,
                                 r"frames: expected an index, a slice or indices of the 4 frames, got \[1000\]"),
    "plot_shapes_frames_text": (lambda: plots.plot_shapes(SHAPE, frames="a"), ArgumentError, r"frames: expected"),
    "plot_shapes_no_frame": (lambda: plots.plot_shapes(SHAPE, frames=[]), ArgumentError,
                             r"frames: selects no frame of the 4"),
    "plot_shapes_max_zero": (lambda: plots.plot_shapes(SHAPE, max_frames=0), ArgumentError,
                             r"max_frames: expected an integer >= 1, got 0"),
    "plot_shapes_max_negative": (lambda: plots.plot_shapes(SHAPE, max_frames=-1), ArgumentError, r"max_frames: "),
    "plot_shapes_cmap": (lambda: plots.plot_shapes(SHAPE, cmap="nope"), ArgumentError,
                         r"cmap: 'nope' is not a matplotlib colour map"),
    "plot_shapes_text": (lambda: plots.plot_shapes("x"), ArgumentError, r"positions_m: expected a Shape"),
    "plot_error_map_empty": (lambda: plots.plot_force_error_map([], [], []), ArgumentError,
                             r"error: no samples to draw"),
    "plot_error_map_cmap": (lambda: plots.plot_force_error_map([1e4], [0.1], [0.0], kind="heatmap", cmap="nope"),
                            ArgumentError, r"cmap: 'nope' is not"),
    "plot_time_series_dict": (lambda: plots.plot_time_series({}), ArgumentError,
                              r"results: expected Results \(bendsense.read_results\) or a results directory, got dict"),
    "plot_results_none": (lambda: plots.plot_results(None), ArgumentError, r"results: expected Results"),
    "plot_results_max_shapes": (lambda: plots.plot_results("r", max_shapes=0), ArgumentError,
                                r"max_shapes: expected an integer >= 1, got 0"),
    "plot_force_shape": (lambda: plots.plot_force(SHAPE), ArgumentError,
                         r"estimate: expected a ForceEstimate \(bendsense.estimate_force\), got Shape"),
    "plot_force_none": (lambda: plots.plot_force(None), ArgumentError, r"estimate: expected a ForceEstimate"),
    "plot_calibration_config": (lambda: plots.plot_calibration(CONFIG), ArgumentError,
                                r"calibration: expected a Calibration \(Calibration.load\(path\)\), got Config"),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_wrong_input_raises_the_librarys_error(name, tmp_path, monkeypatch):
    import matplotlib.pyplot as plt

    monkeypatch.chdir(tmp_path)
    call, error, match = CASES[name]
    figures = plt.get_fignums()
    with pytest.raises(error, match=match) as info:
        call()
    assert isinstance(info.value, BendsenseError)
    assert list(tmp_path.iterdir()) == []  # nothing written
    assert plt.get_fignums() == figures  # no figure left open


def test_process_accepts_paths_for_the_session_the_config_and_the_calibration():
    config_path = bendsense.config.resources.files("bendsense.data").joinpath(bendsense.config.PAPER_CONFIG)
    by_path = process(str(GOOD_CSV), str(config_path), str(GOOD_CAL), estimate=False)
    by_object = process(SESSION, CONFIG, CAL, estimate=False)
    assert by_path.session.source == str(GOOD_CSV)
    np.testing.assert_array_equal(by_path.shape.curvature_per_m, by_object.shape.curvature_per_m)
