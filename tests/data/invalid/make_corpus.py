"""Generate the bad-input corpus under tests/data/invalid: python tests/data/invalid/make_corpus.py

The cases are committed; run this only to regenerate them after a deliberate change of a
message (then review the diff). Configs and the older session CSVs are written by hand.
"""
import os
import shutil
import sys
from pathlib import Path

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[3]
ROOT = REPO / "tests" / "data" / "invalid"
sys.path.insert(0, str(REPO / "src"))
from bendsense.session.native import SessionWriter, record_dtype  # noqa: E402

N = 16
OFFSET = [2000.0 + 10 * i for i in range(N)]


def csv_text(rows=4, n=N, pressure="pressure_kpa", scale=1.0, delta=50.0):
    head = ["t_s"] + ([pressure] if pressure else []) + [f"ch{i + 1}" for i in range(n)]
    lines = [",".join(head)]
    for k in range(rows):
        cells = [f"{k * 0.01:g}"] + ([f"{(20 + 20 * k) * scale:g}"] if pressure else [])
        cells += [f"{OFFSET[i % N] + (delta if i % 2 == 0 else -delta) * (k + 1) / rows:g}" for i in range(n)]
        lines.append(",".join(cells))
    return "\n".join(lines) + "\n"


def put(path: Path, data, expect: str | None = None, sidecar: bool = False):
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(data, str):
        data = data.encode("utf-8")
    if expect is not None and not sidecar:
        data = f"# expect: {expect}\n".encode() + data
    path.write_bytes(data)
    if expect is not None and sidecar:
        path.with_name(path.name + ".expect").write_text(expect + "\n", encoding="utf-8")


# ---- a good session and its recordings (inputs of the CLI cases)
good = ROOT / "good"
shutil.rmtree(good, ignore_errors=True)
put(good / "session.csv", csv_text())
put(good / "session_ch8.csv", csv_text(n=8))
put(good / "free_bending_pa_holds_kpa.csv", "pressure_pa,bending_angle_deg\n20,25\n60,80\n120,176\n")

# ---- sessions (CSV): first line "# expect: REGEX", or a .expect sidecar
S = ROOT / "sessions"
put(S / "semicolon.csv", csv_text().replace(",", ";"), r"line 2: columns are separated by ';', expected ','")
put(S / "tabs.csv", csv_text().replace(",", "\t"), r"line 2: columns are separated by tabs, expected ','")
put(S / "binary.csv", bytes(range(256)) * 4, r"binary data, not a session CSV \(NUL byte at byte offset 0\)", True)
put(S / "utf16.csv", csv_text().encode("utf-16"), r"UTF-16 text, not UTF-8; save the file as UTF-8", True)
put(S / "gzip.csv", b"\x1f\x8b\x08\x00" + bytes(range(200)), r"binary data, not a session CSV", True)
put(S / "pressure_kpa_holds_pa.csv", csv_text(pressure="pressure_kpa", scale=1000),
    r"line 2, column pressure_kpa: readings up to 80000 kPa \(over 1 MPa\); looks like pascals")
put(S / "long_cell.csv", "t_s,ch1\n0," + "x" * 100000 + "\n",
    r"line 3, column ch1: expected a number, got 'x{40,}\.\.\.$")
put(S / "inf_channel.csv", "t_s,ch1,ch2\n0,1,inf\n", r"line 3, column ch2: must be finite, got 'inf'")
put(S / "only_comments.csv", "# a: 1\n# b: 2\n", r"no header row")
put(S / "pressure_text.csv", "t_s,pressure_kpa,ch1\n0,abc,1\n", r"line 3, column pressure_kpa: expected a number, got 'abc'")
put(S / "t_s_text.csv", "t_s,ch1\nnoon,1\n", r"line 3, column t_s: expected a number, got 'noon'")
put(S / "ch0.csv", "t_s,ch0,ch1\n0,1,2\n", r"line 2, column ch0: signal columns are numbered from 1")
put(S / "ch01.csv", "t_s,ch01,ch02\n0,1,2\n", r"line 2, column ch01: signal columns are numbered from 1")
put(S / "empty_header_cell.csv", "t_s,,ch1\n0,1,2\n", r"line 2: empty column name in header")
put(S / "row_too_long.csv", "t_s,ch1\n0,1\n1,2,3\n", r"line 4: expected 2 columns, got 3")
# time that does not increase strictly (docs/formats.md, "Time"): refused with the first rows
rows4 = csv_text(rows=6).splitlines()
put(S / "t_backwards.csv", "\n".join(rows4[:4] + [rows4[4].replace("0.03,", "0.01,", 1)] + rows4[5:]) + "\n",
    r"line 6, column t_s: time runs backwards \(0\.01 s after 0\.02 s on line 5\); t_s must increase from row to row")
put(S / "t_repeated.csv", "\n".join(rows4[:3] + [rows4[3].replace("0.02,", "0.01,", 1)] + rows4[4:]) + "\n",
    r"line 5, column t_s: time repeats \(0\.01 s after 0\.01 s on line 4\)")
put(S / "t_shuffled.csv", "\n".join([rows4[0], rows4[3], rows4[1], rows4[5], rows4[2], rows4[6], rows4[4]]) + "\n",
    r"line 4, column t_s: time runs backwards \(0 s after 0\.02 s on line 3\); 3 rows out of order in all "
    r"\(also lines 6, 8\)")
put(S / "t_all_equal.csv", "t_s,ch1\n5,1\n5,2\n5,3\n", r"line 4, column t_s: time repeats \(5 s after 5 s on line 3\)")
put(S / "nul_in_middle.csv", csv_text()[:40] + "\x00" + csv_text()[40:],
    r"binary data, not a session CSV \(NUL byte at byte offset \d+\)")

# ---- calibrations: Calibration.load
C = ROOT / "calibrations"
base = (REPO / "tests" / "data" / "calibration" / "calibration_v1.yaml").read_text()
cal = yaml.safe_load(base)


def cal_case(name, expect, change=None, text=None, sidecar=False, raw=None):
    if raw is not None:
        put(C / name, raw, expect, True)
        return
    if text is None:
        d = dict(cal)
        change(d)
        text = yaml.safe_dump(d, sort_keys=False)
    put(C / name, text, expect, sidecar)


cal_case("not_yaml.yaml", r"not valid YAML: .* \(line \d+, column \d+\)", text="offset: [1, 2\nformat: x: y\n")
cal_case("top_level_list.yaml", r"calibration: expected a mapping \(format: bendsense-calibration\), got \[1, 2\]", text="- 1\n- 2\n")
cal_case("empty.yaml", r"calibration: expected a mapping \(format: bendsense-calibration\), got None", text="")
cal_case("wrong_format.yaml", r"format: expected 'bendsense-calibration', got 'bendsense-config'",
         lambda d: d.update(format="bendsense-config"))
cal_case("future_version.yaml", r"version: this bendsense reads version", lambda d: d.update(version=99))
cal_case("offset_strings.yaml", r"offset: expected a list of numbers", lambda d: d.update(offset=["a"] * 16))
cal_case("offset_nan.yaml", r"offset: values must be finite", lambda d: d.update(offset=[float("nan")] * 16))
cal_case("n_channels_mismatch.yaml", r"n_channels: 8 does not match the 16 offset values",
         lambda d: d.update(n_channels=8))
cal_case("noise_negative.yaml", r"noise_std: values must be >= 0", lambda d: d.update(noise_std=[-0.5] * 16))
cal_case("weighting_unknown.yaml", r"weighting: must be one of none, shift, got 'heavy'",
         lambda d: d.update(weighting="heavy"))
cal_case("sleeve_string.yaml", r"sleeve: expected true or false, got 'yes please'",
         lambda d: d.update(sleeve="yes please"))
cal_case("missing_offset.yaml", r"calibration: missing keys offset", lambda d: d.pop("offset"))
cal_case("unknown_key.yaml", r"calibration: unknown keys colour", lambda d: d.update(colour="red"))
cal_case("latin1.yaml", r"not UTF-8 text \(byte offset \d+, line 1\)", raw=("# caf\u00e9\n" + base).encode("latin-1"))
cal_case("binary.yaml", r"binary data, not a calibration \(NUL byte at byte offset 3\)", raw=b"abc\x00def")
bomb = ["a0: &a0 [" + ", ".join(["1"] * 9) + "]"] + [
    f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 9)]
cal_case("alias_bomb.yaml", r"YAML expands to more than 50,000 nodes through aliases", text="\n".join(bomb) + "\n")
cal_case("alias_loop.yaml", r"YAML alias refers to itself", text="offset: &o [1, *o]\n")
cal_case("coefficients_not_list.yaml", r"coefficients_odd: expected a list of numbers",
         lambda d: d.update(coefficients_odd="1e-6"))
cal_case("range_reversed.yaml", r"delta_a_range_odd: expected \[min, max\] with min <= max",
         lambda d: d.update(delta_a_range_odd=[600.0, 0.0]))


# impossible counts and values on the σ path (issue 21): every field a reader uses is checked


def strip(i, **change):
    def edit(d):
        d["strip_residuals"] = [dict(r) for r in d["strip_residuals"]]
        d["strip_residuals"][i].update(change)
    return edit


def fit_rows(rows, n=N, value=0.0):
    return lambda d: d.update(fit_delta_a=[[value] * n for _ in range(rows)], fit_shifts_m=[[0.0] * n for _ in range(rows)])


cal_case("strip_n_frames_negative.yaml", r"strip_residuals\[0\]\.n_frames: expected an integer >= 1, got -5",
         strip(0, n_frames=-5))
cal_case("strip_n_frames_zero.yaml", r"strip_residuals\[1\]\.n_frames: expected an integer >= 1, got 0",
         strip(1, n_frames=0))
cal_case("strip_n_frames_float.yaml", r"strip_residuals\[0\]\.n_frames: expected an integer, got 200\.5",
         strip(0, n_frames=200.5))
cal_case("strip_radius_negative.yaml", r"strip_residuals\[0\]\.radius_m: expected > 0, got -0\.04",
         strip(0, radius_m=-0.04))
cal_case("strip_rms_nan.yaml", r"strip_residuals\[1\]\.rms_shift_m: expected a finite number, got nan",
         strip(1, rms_shift_m=float("nan")))
cal_case("strip_max_below_rms.yaml", r"strip_residuals\[0\]\.max_abs_shift_m: 1e-07 is below its rms_shift_m 1\.2e-06",
         strip(0, max_abs_shift_m=1e-7))
cal_case("strip_signal_std_negative.yaml", r"strip_residuals\[1\]\.signal_std: expected >= 0, got -0\.55",
         strip(1, signal_std=-0.55))
cal_case("strip_unknown_key.yaml", r"strip_residuals\[0\]: unknown keys frames; allowed: radius_m",
         strip(0, frames=200))
cal_case("strip_not_mapping.yaml", r"strip_residuals\[0\]: expected a mapping with keys radius_m",
         lambda d: d.update(strip_residuals=["r040.csv"]))
cal_case("strip_residuals_mapping.yaml", r"strip_residuals: expected a list of mappings",
         lambda d: d.update(strip_residuals={"r040.csv": 1}))
cal_case("flat_frames_zero.yaml", r"meta\.flat_frames: expected an integer >= 1, got 0",
         lambda d: d.update(meta={**d["meta"], "flat_frames": 0}))
cal_case("flat_frames_negative.yaml", r"meta\.flat_frames: expected an integer >= 1, got -5",
         lambda d: d.update(meta={**d["meta"], "flat_frames": -5}))
cal_case("flat_frames_text.yaml", r"meta\.flat_frames: expected an integer, got 'many'",
         lambda d: d.update(meta={**d["meta"], "flat_frames": "many"}))
cal_case("flat_frames_one_with_noise.yaml", r"meta\.flat_frames: 1 frame cannot have given noise_std",
         lambda d: d.update(meta={**d["meta"], "flat_frames": 1}))
cal_case("cv_error_text.yaml", r"cv_errors_m\[2\]: expected a number, got 'small'",
         lambda d: d.update(cv_errors_m={2: "small"}))
cal_case("cv_error_negative.yaml", r"cv_errors_m\[1\]: expected >= 0, got -1e-06", lambda d: d.update(cv_errors_m={1: -1e-6}))
cal_case("cv_degree_text.yaml", r"cv_errors_m key 'two': expected an integer, got 'two'",
         lambda d: d.update(cv_errors_m={"two": 1e-6}))
cal_case("fit_rows_vs_strips.yaml", r"fit_delta_a: expected 3 rows \(the flat recording and 2 strips of strip_residuals\), got 2",
         fit_rows(2))
cal_case("fit_delta_a_nan.yaml", r"fit_delta_a\[0\]: values must be finite", fit_rows(3, value=float("nan")))
cal_case("fit_shifts_8_channels.yaml", r"fit_delta_a\[0\]: expected 16 numbers, got 8", fit_rows(3, n=8))
cal_case("fit_delta_a_flat_list.yaml", r"fit_delta_a: expected a list of rows of 16 numbers",
         lambda d: d.update(fit_delta_a=[0.0] * 16, fit_shifts_m=[0.0] * 16))

# ---- manifests: Calibration.fit(manifest); recordings in manifests/rec/
M = ROOT / "manifests"
rec = M / "rec"
shutil.rmtree(rec, ignore_errors=True)
put(rec / "flat.csv", csv_text(pressure=None, delta=0.0))
put(rec / "r040.csv", csv_text(pressure=None, delta=300.0))
put(rec / "r080.csv", csv_text(pressure=None, delta=150.0))
put(rec / "ch8.csv", csv_text(n=8, pressure=None))
put(rec / "semicolon.csv", csv_text(pressure=None).replace(",", ";"))
put(rec / "binary.csv", bytes(range(256)))


def man(name, expect, data=None, text=None, raw=None):
    if raw is not None:
        put(M / name, raw, expect, True)
        return
    put(M / name, text if text is not None else yaml.safe_dump(data, sort_keys=False), expect)


ok = [{"radius_m": 0.04, "recording": "rec/r040.csv"}, {"radius_mm": 80, "recording": "rec/r080.csv"}]
man("radius_in_mm.yaml", r"strips\[0\]\.radius_m: expected a length in metres <= 1, got 40; looks like millimetres",
    {"flat": "rec/flat.csv", "strips": [{"radius_m": 40, "recording": "rec/r040.csv"}]})
man("radius_mm_in_m.yaml", r"strips\[1\]\.radius_mm: expected a radius in millimetres >= 1, got 0\.08; looks like metres",
    {"flat": "rec/flat.csv", "strips": [ok[0], {"radius_mm": 0.08, "recording": "rec/r080.csv"}]})
man("duplicate_strip.yaml", r"strips\[1\]\.recording: r040\.csv is listed twice \(strips\[0\] too\)",
    {"flat": "rec/flat.csv", "strips": [ok[0], {"radius_m": 0.05, "recording": "rec/r040.csv"}]})
man("flat_as_strip.yaml", r"strips\[0\]\.recording: flat\.csv is the flat recording too",
    {"flat": "rec/flat.csv", "strips": [{"radius_m": 0.04, "recording": "rec/flat.csv"}]})
man("negative_radius.yaml", r"strips\[0\]\.radius_m: expected > 0, got -0\.04",
    {"flat": "rec/flat.csv", "strips": [{"radius_m": -0.04, "recording": "rec/r040.csv"}]})
man("radius_string.yaml", r"strips\[0\]\.radius_m: expected a number, got '40 mm'",
    {"flat": "rec/flat.csv", "strips": [{"radius_m": "40 mm", "recording": "rec/r040.csv"}]})
man("radius_bool.yaml", r"strips\[0\]\.radius_m: expected a number, got True",
    {"flat": "rec/flat.csv", "strips": [{"radius_m": True, "recording": "rec/r040.csv"}]})
man("radius_nan.yaml", r"strips\[0\]\.radius_m: expected a finite number, got nan",
    text="flat: rec/flat.csv\nstrips:\n  - {radius_m: .nan, recording: rec/r040.csv}\n")
man("missing_flat.yaml", r"flat: missing key", {"strips": ok})
man("no_flat_file.yaml", r"flat: no such recording 'nothere\.csv'", {"flat": "nothere.csv", "strips": ok})
man("unknown_top_key.yaml", r"strip: unknown key; allowed: flat, strips", {"flat": "rec/flat.csv", "strip": ok})
man("strips_empty.yaml", r"strips: expected a non-empty list", {"flat": "rec/flat.csv", "strips": []})
man("strips_mapping.yaml", r"strips: expected a non-empty list", {"flat": "rec/flat.csv", "strips": {"a": 1}})
man("strip_not_mapping.yaml", r"strips\[0\]: expected a mapping with radius_m or radius_mm and recording",
    {"flat": "rec/flat.csv", "strips": ["rec/r040.csv"]})
man("strip_unknown_key.yaml", r"strips\[0\]\.radius_cm: unknown key",
    {"flat": "rec/flat.csv", "strips": [{"radius_cm": 4, "recording": "rec/r040.csv"}]})
man("both_radii.yaml", r"strips\[0\]: give exactly one of radius_m, radius_mm, got both",
    {"flat": "rec/flat.csv", "strips": [{"radius_m": 0.04, "radius_mm": 40, "recording": "rec/r040.csv"}]})
man("radius_tiny.yaml", r"strips\[0\]\.radius_m: expected a strip radius of at least 1 mm \(0\.001 m\), got 1e-300 m",
    {"flat": "rec/flat.csv", "strips": [{"radius_m": 1e-300, "recording": "rec/r040.csv"}]})
man("no_recording.yaml", r"strips\[0\]: missing key recording", {"flat": "rec/flat.csv", "strips": [{"radius_m": 0.04}]})
man("recording_number.yaml", r"strips\[0\]\.recording: expected a file name, got 40",
    {"flat": "rec/flat.csv", "strips": [{"radius_m": 0.04, "recording": 40}]})
man("recording_8_channels.yaml", r"strips\[0\]\.recording \(ch8\.csv\): expected 16 channels \(sensor\.n_segments\), got 8",
    {"flat": "rec/flat.csv", "strips": [{"radius_m": 0.04, "recording": "rec/ch8.csv"}]})
man("recording_semicolons.yaml", r"semicolon\.csv: line 1: columns are separated by ';'",
    {"flat": "rec/flat.csv", "strips": [{"radius_m": 0.04, "recording": "rec/semicolon.csv"}]})
man("recording_binary.yaml", r"binary\.csv: binary data, not a session CSV",
    {"flat": "rec/flat.csv", "strips": [{"radius_m": 0.04, "recording": "rec/binary.csv"}]})
man("top_level_list.yaml", r"manifest: expected a mapping with keys flat, strips, got \['rec/flat\.csv'\]",
    text="- rec/flat.csv\n")
man("not_yaml.yaml", r"not valid YAML: .*\(line \d+, column \d+\)", text="flat: [rec/flat.csv\nstrips: {\n")
man("duplicate_key.yaml", r"duplicate key 'strips' \(line 4; first on line 3\)",
    text="flat: rec/flat.csv\nstrips: []\nstrips:\n  - {radius_m: 0.04, recording: rec/r040.csv}\n")
man("alias_bomb.yaml", r"YAML expands to more than 50,000 nodes", text="\n".join(bomb) + "\n")
man("latin1.yaml", r"not UTF-8 text \(byte offset \d+, line 1\)", raw="# r\u00e9glage\nflat: rec/flat.csv\n".encode("latin-1"))
man("binary.yaml", r"binary data, not a manifest", raw=b"\x00\x01\x02flat")
man("utf16.yaml", r"UTF-16 text, not UTF-8", raw="flat: rec/flat.csv\n".encode("utf-16"))
man("recording_dev_zero.yaml", r"flat: recording '/dev/zero' is a character device, not a session CSV",
    {"flat": "/dev/zero", "strips": ok})

# ---- native sessions: directories; "expect" holds the regex
NAT = ROOT / "native"
shutil.rmtree(NAT, ignore_errors=True)


def native(name, expect, records=40, mutate_meta=None, mutate_bytes=None, n=N, adc_bits=12, cli_only=False):
    d = NAT / name
    with SessionWriter(d, record_dtype(n), adc_bits=adc_bits, device={"firmware": "corpus"}) as w:
        rec = w.empty(records)
        rec["t_us"] = np.arange(records) * 2000
        rec["host_ns"] = np.arange(records) * 2_000_000
        rec["seq"] = np.arange(records)
        rec["pressure_pa"] = 50_000
        rec["adc"] = np.array(OFFSET[:n], dtype=np.uint16)
        if records:
            w.write(rec)
    if mutate_meta is not None:
        meta = yaml.safe_load((d / "meta.yaml").read_text())
        mutate_meta(meta)
        (d / "meta.yaml").write_text(yaml.safe_dump(meta, sort_keys=False))
    if mutate_bytes is not None:
        data = (d / "frames.bin").read_bytes()
        (d / "frames.bin").write_bytes(mutate_bytes(data))
    (d / "expect").write_text(expect + ("\ncli-only" if cli_only else "") + "\n")


size = 8 + 8 + 2 + 1 + 2 + 4 + 2 * N
native("truncated", r"frames\.bin: 19 of 40 records present; 21 lost, and a torn record of 7 bytes",
       mutate_bytes=lambda b: b[: 19 * size + 7])
native("truncated_whole", r"frames\.bin: 10 of 40 records present; 30 lost \(frames\.bin was cut short",
       mutate_bytes=lambda b: b[: 10 * size])
native("frames_missing", r"frames\.bin: 0 of 40 records present; 40 lost", mutate_bytes=lambda b: b"")
native("extra_records", r"frames\.bin: 45 records present, but meta\.yaml recorded 40",
       mutate_bytes=lambda b: b + b[: 5 * size])
native("stray_bytes", r"frames\.bin: 5 stray bytes after the 40 records", mutate_bytes=lambda b: b + b"\x01" * 5)
native("record_size_edited", rf"record_size is 60 bytes, but record_dtype gives {size}-byte records",
       mutate_meta=lambda m: m.update(record_size=60))


def set_field(m, name, spec):
    m["record_dtype"] = [[k, spec if k == name else v] for k, v in m["record_dtype"]]


native("dtype_big_endian", r"field adc: expected \(N,\) of <u2, <f4, <f8, got '\(16,\)>u2'",
       mutate_meta=lambda m: set_field(m, "adc", "(16,)>u2"))
native("dtype_pressure_float", r"field pressure_pa: expected <i4, got <f4",
       mutate_meta=lambda m: set_field(m, "pressure_pa", "<f4"))
native("dtype_garbage", r"meta\.yaml record_dtype: invalid", mutate_meta=lambda m: set_field(m, "adc", "(16,)<zz"))
native("dtype_missing_field", r"meta\.yaml record_dtype: missing fields \['tx_drops'\]",
       mutate_meta=lambda m: m.update(record_dtype=[p for p in m["record_dtype"] if p[0] != "tx_drops"]))
native("dtype_not_list", r"record_dtype: expected a list of \[name, dtype\] pairs, got '<u2'",
       mutate_meta=lambda m: m.update(record_dtype="<u2"))
native("adc_channels_edited", r"field adc: expected 8 values \(n_channels\), got 16",
       mutate_meta=lambda m: m.update(n_channels=8))
native("adc_bits_edited", r"ADC counts up to 2,150 do not fit adc_bits 8", mutate_meta=lambda m: m.update(adc_bits=8))
native("version_3", r"version: expected 1 or 2, got 3", mutate_meta=lambda m: m.update(version=3))
native("format_other", r"format: expected 'bendsense-session', got 'csv'", mutate_meta=lambda m: m.update(format="csv"))
native("missing_record_dtype", r"meta\.yaml: missing record_dtype", mutate_meta=lambda m: m.pop("record_dtype"))
native("finished_text", r"finished: expected true or false, got 'yes'", mutate_meta=lambda m: m.update(finished="yes"))
native("n_records_negative", r"n_records: expected an integer >= 0, got -3", mutate_meta=lambda m: m.update(n_records=-3))
native("n_channels_text", r"n_channels: expected an integer, got 'sixteen'",
       mutate_meta=lambda m: m.update(n_channels="sixteen"))
native("empty_recording", r"no frames \(an empty recording\)", records=0, cli_only=True)
for name, data, expect in [
    ("meta_latin1", "# caf\u00e9\n".encode("latin-1"), r"meta\.yaml: not UTF-8 text \(byte offset \d+, line 1\)"),
    ("meta_binary", b"\x00\x01", r"meta\.yaml: binary data, not a session meta\.yaml"),
    ("meta_not_yaml", b"format: [bendsense-session\n", r"meta\.yaml: not valid YAML"),
    ("meta_alias_bomb", ("\n".join(bomb) + "\n").encode(), r"meta\.yaml: YAML expands to more than 50,000 nodes"),
    ("meta_list", b"- 1\n", r"meta\.yaml: format: expected 'bendsense-session', got 'list'"),
]:
    native(name, expect)
    (NAT / name / "meta.yaml").write_bytes(data)
d = NAT / "meta_missing"
native("meta_missing", r"not a session directory \(no meta\.yaml\)")
(d / "meta.yaml").unlink()
print("ok")

# ---- command lines: args (placeholders {good_csv}, {good_cal}, {invalid}) and the message
CLI = ROOT / "cli"
shutil.rmtree(CLI, ignore_errors=True)
CLI.mkdir()
cases = {
    "simulate_negative_seed": ("simulate calibration -o sim --seed -1", r"'--seed': -1 is not in the range 0<=x<=4294967295"),
    "reproduce_negative_seed": ("reproduce -o rep --quick --seed -5", r"'--seed': -5 is not in the range"),
    "demo_negative_seed": ("demo -o d --seed -1", r"'--seed': -1 is not in the range"),
    "simulate_frames_zero": ("simulate validation -o sim --frames 0", r"'--frames': 0 is not in the range x>=1"),
    "simulate_noise_nan": ("simulate validation -o sim --noise-counts nan", r"'--noise-counts': expected a finite number, got nan"),
    "simulate_hysteresis_negative": ("simulate contact -o sim --hysteresis-kpa -1", r"'--hysteresis-kpa': expected >= 0, got -1"),
    "simulate_bad_config": ("simulate calibration -o sim --config {invalid}/configs/segment_lengths_mm.yaml",
                            r"segment_lengths_mm\.yaml: sensor\.segment_lengths_m\[0\] = 10 .* if it was entered in mm, it is 0\.01 m"),
    "record_seconds_nan": ("record loop:// -o rec --seconds nan", r"'--seconds': expected a finite number, got nan"),
    "record_seconds_inf": ("record loop:// -o rec --seconds inf", r"'--seconds': expected a finite number, got inf"),
    "record_seconds_negative": ("record loop:// -o rec --seconds -3", r"'--seconds': expected > 0, got -3"),
    "record_seconds_zero": ("record loop:// -o rec --seconds 0", r"'--seconds': expected > 0, got 0"),
    "record_seconds_text": ("record loop:// -o rec --seconds soon", r"'--seconds': 'soon' is not a valid float"),
    "record_hello_timeout_nan": ("record loop:// -o rec --hello-timeout nan", r"'--hello-timeout': expected a finite number"),
    "record_hello_timeout_negative": ("record loop:// -o rec --hello-timeout -1", r"'--hello-timeout': expected > 0, got -1"),
    "record_no_such_port": ("record /dev/nonexistent-bendsense -o rec --seconds 1",
                            r"/dev/nonexistent-bendsense: cannot open serial port"),
    "record_unknown_url": ("record nosuch://x -o rec --seconds 1", r"nosuch://x: cannot open serial port"),
    "record_line_without_channels": ("record loop:// -o rec --dialect line", r"the line dialect needs --channels or --columns"),
    "sim_device_drop_nan": ("sim-device --drop nan", r"'--drop': expected a finite number, got nan"),
    "sim_device_drop_above_one": ("sim-device --drop 1.5", r"'--drop': expected <= 1, got 1\.5"),
    "sim_device_rate_zero": ("sim-device --rate 0", r"'--rate': expected > 0, got 0"),
    "sim_device_seconds_inf": ("sim-device --seconds inf", r"'--seconds': expected a finite number, got inf"),
    "live_seconds_nan": ("live loop:// --calibration {good_cal} --seconds nan", r"'--seconds': expected a finite number"),
    "live_save_bad_suffix": ("live loop:// --calibration {good_cal} --save live.xyz", r"live\.xyz: unknown figure format '\.xyz'"),
    "live_no_calibration": ("live loop://", r"live needs a sensor calibration"),
    "load_pressure_nan": ("load {good_csv} --pressure-kpa nan", r"'--pressure-kpa': expected a finite number, got nan"),
    "load_pressure_inf": ("load {good_csv} --pressure-kpa inf", r"'--pressure-kpa': expected a finite number, got inf"),
    "load_missing_file": ("load nothere.csv", r"'nothere\.csv' does not exist"),
    "load_channels_vs_calibration": ("load {invalid}/good/session_ch8.csv --calibration {good_cal} reconstruct save out",
                                     r"session_ch8\.csv: 8 signal channels \(ch1\.\.ch8\), but the calibration .*calibration_v1\.yaml has 16"),
    "reconstruct_without_load": ("reconstruct", r"'reconstruct' needs 'load SESSION' earlier in the chain"),
    "reconstruct_without_calibration": ("load {good_csv} reconstruct", r"'reconstruct' needs 'load \.\.\. --calibration CAL\.yaml'"),
    "estimate_without_reconstruct": ("load {good_csv} estimate", r"'estimate' needs 'reconstruct' earlier in the chain"),
    "estimate_push_only_unconstrained": ("load {good_csv} --calibration {good_cal} reconstruct estimate --push-only save out",
                                         r"push_only: only for the 1-D constraints"),
    "estimate_unknown_constraint": ("load {good_csv} --calibration {good_cal} reconstruct estimate --constraint sideways",
                                    r"'--constraint': 'sideways' is not one of"),
    "save_without_reconstruct": ("load {good_csv} save out", r"'save' needs 'reconstruct' earlier in the chain"),
    "plot_bad_suffix_in_chain": ("load {good_csv} --calibration {good_cal} reconstruct save out plot fig.xyz",
                                 r"fig\.xyz: unknown figure format '\.xyz'"),
    "plot_no_suffix": ("load {good_csv} --calibration {good_cal} reconstruct plot figure", r"figure: no figure format \(a file name suffix\)"),
    "plot_results_bad_suffix": ("plot {invalid}/good -o fig.docx", r"fig\.docx: unknown figure format '\.docx'"),
    "plot_not_results_dir": ("plot {invalid}/good -o fig.png", r"good: no results\.csv \(not a results directory\)"),
    "plot_without_reconstruct": ("plot fig.png", r"'plot FIG' needs 'reconstruct' earlier in the chain"),
    "calibrate_plot_bad_suffix": ("calibrate {invalid}/manifests/duplicate_strip.yaml -o cal.yaml --plot fit.xyz",
                                  r"fit\.xyz: unknown figure format '\.xyz'"),
    "calibrate_degree_bad": ("calibrate {invalid}/manifests/duplicate_strip.yaml -o cal.yaml --degree 9",
                             r"'--degree': expected 1\.\.5 or 'auto', got '9'"),
    "identify_fix_not_a_number": ("identify free-bending {good_csv} -o cfg.yaml --fix mu=soft",
                                  r"--fix shear_modulus_pa: expected a number, got 'soft'"),
    "identify_fix_nan": ("identify free-bending {good_csv} -o cfg.yaml --fix mu=nan",
                         r"--fix shear_modulus_pa: expected a finite number, got nan"),
    "identify_plot_bad_suffix": ("identify free-bending {good_csv} -o cfg.yaml --plot p.abc", r"p\.abc: unknown figure format"),
    "identify_semicolon_csv": ("identify free-bending {invalid}/sessions/semicolon.csv -o cfg.yaml",
                               r"semicolon\.csv: line 2: columns are separated by ';'"),
    "identify_binary_csv": ("identify stiffness {invalid}/sessions/binary.csv -o cfg.yaml", r"binary\.csv: binary data"),
    "process_scheduler_garbage": ("process {good_csv} --calibration {good_cal} -o out --scheduler 'not an address'",
                                  r"--scheduler: expected tcp://HOST:PORT, got 'not an address'"),
    "process_pressure_nan": ("process {good_csv} --calibration {good_cal} -o out --pressure-kpa nan",
                             r"'--pressure-kpa': expected a finite number"),
    "process_bad_calibration": ("process {good_csv} --calibration {invalid}/calibrations/alias_bomb.yaml -o out",
                                r"alias_bomb\.yaml: YAML expands to more than 50,000 nodes"),
    "process_bad_config": ("process {good_csv} --calibration {good_cal} --config {invalid}/configs/pressure_range_kpa.yaml -o out",
                           r"pressure_range_kpa\.yaml: actuator\.pressure_range_pa\[1\] = 200 .* if it was entered in kPa, it is 200000 Pa"),
    "unknown_command": ("fly", r"No such command 'fly'"),
    # unit slips in held model parameters and pressure options (issue 21)
    "simulate_ei_error_percent": ("simulate validation -o sim --ei-error 20",
                                 r"--ei-error = 20 is not a plausible relative error .*; if it was entered in percent, it is 0\.2"),
    "identify_fix_ei1_per_kpa": ("identify stiffness {good_csv} -o cfg.yaml --fix ei1=1.25e-5",
                                r"--fix ei1_nm2_per_pa = 1\.25e-5 is not a plausible pressure stiffening .*; if it was entered in N·m²/kPa, it is 1\.25e-8 N·m²/Pa"),
    "identify_fix_ei0_n_mm2": ("identify stiffness {good_csv} -o cfg.yaml --fix ei0=2530",
                              r"--fix ei0_nm2 = 2530 is not a plausible bending stiffness .*; if it was entered in N·mm², it is 0\.00253 N·m²"),
    "identify_fix_prebend_degrees": ("identify free-bending {good_csv} -o cfg.yaml --fix prebend=5",
                                    r"--fix prebend_angle_rad = 5 is not a plausible prebend angle .*; if it was entered in degrees, it is 0\.0872665 rad"),
    "identify_fix_mu_mpa": ("identify free-bending {good_csv} -o cfg.yaml --fix mu=0.18",
                           r"--fix shear_modulus_pa = 0\.18 is not a plausible shear modulus .*; if it was entered in MPa, it is 180000 Pa"),
    "load_pressure_kpa_in_pa": ("load {good_csv} --pressure-kpa 200000",
                               r"--pressure-kpa = 200000 is not a plausible gauge pressure .*; if it was entered in Pa, it is 200 kPa"),
    "process_pressure_kpa_in_pa": ("process {good_csv} --calibration {good_cal} -o out --pressure-kpa 60000",
                                  r"--pressure-kpa = 60000 is not a plausible gauge pressure .*; if it was entered in Pa, it is 60 kPa"),
    "identify_pressure_pa_holds_kpa": ("identify free-bending {invalid}/good/free_bending_pa_holds_kpa.csv -o cfg.yaml",
                                       r"free_bending_pa_holds_kpa\.csv: line 1, column pressure_pa: every reading is below "
                                       r"1 kPa \(largest 120\); looks like kilopascals"),
}
# inputs that are not files, and what the machine cannot do
cases.update({
    "load_dev_zero": ("load /dev/zero --calibration {good_cal} reconstruct save out",
                      r"^Error: /dev/zero: a character device, not a session \(a session CSV or a native session directory\)"),
    "load_calibration_dev_zero": ("load {good_csv} --calibration /dev/zero reconstruct save out",
                                  r"^Error: /dev/zero: a character device, not a calibration"),
    "load_config_dev_zero": ("load {good_csv} --config /dev/zero --calibration {good_cal} reconstruct save out",
                             r"^Error: /dev/zero: a character device, not a config"),
    "calibrate_dev_zero": ("calibrate /dev/zero -o cal.yaml", r"^Error: /dev/zero: a character device, not a manifest"),
    "process_dev_zero": ("process /dev/zero --calibration {good_cal} -o out", r"^Error: /dev/zero: a character device"),
    "identify_dev_zero": ("identify stiffness /dev/zero -o cfg.yaml", r"^Error: /dev/zero: a character device, not a CSV"),
    "identify_config_dev_zero": ("identify free-bending {good_csv} -o cfg.yaml --config /dev/zero",
                                 r"^Error: /dev/zero: a character device, not a config"),
    "sim_device_replay_dev_zero": ("sim-device --replay /dev/zero", r"^Error: /dev/zero: a character device, not a session"),
    "plot_results_dev_null": ("plot /dev/null -o fig.png", r"/dev/null"),
    "sim_device_rate_beyond_the_link": ("sim-device --rate 1e9",
                                        r"--rate: expected at most 22,943 Hz \(what a USB full-speed link carries"),
    "demo_rate_beyond_the_link": ("demo -o d --rate 100000", r"--rate: expected at most 22,943 Hz"),
    "load_twice": ("load {good_csv} --calibration {good_cal} reconstruct save a load {good_csv} reconstruct save b",
                   r"'load' given 2 times \(.*session\.csv, .*session\.csv\); a chain processes one session"),
    "record_baud_zero": ("record loop:// -o rec --baud 0", r"'--baud': 0 is not in the range 50<=x<=12000000"),
    "record_baud_negative": ("record loop:// -o rec --baud -9600", r"'--baud': -9600 is not in the range"),
    "live_baud_absurd": ("live loop:// --calibration {good_cal} --baud 1000000000",
                         r"'--baud': 1000000000 is not in the range 50<=x<=12000000"),
    "simulate_frames_beyond_memory": ("simulate tip-loads -o sim --frames 100000000",
                                      r"--frames: tip-loads would hold 4,400,000,000 frames in memory, about 52\.8 TB; "
                                      r"this machine has .* available"),
})
# outputs: two steps writing one file, and output paths through symbolic links that lead elsewhere
# (links/dangling -> ../no-such-directory/results; links/outward -> ../results)
LINKS = ROOT / "links"
shutil.rmtree(LINKS, ignore_errors=True)
LINKS.mkdir()
os.symlink("../no-such-directory/results", LINKS / "dangling")
os.symlink("../results", LINKS / "outward")
LOADED = "load {good_csv} --calibration {good_cal} reconstruct"
cases.update({
    "save_then_export_its_results_csv": (f"{LOADED} save out export out/results.csv --overwrite",
                                         r"^Error: out/results\.csv: written by two steps of this command line, "
                                         r"'save' and 'export'; give each step its own output"),
    "plot_twice_one_path": (f"{LOADED} plot fig.png plot ./fig.png",
                            r"fig\.png: written by two steps .*'plot' \(step 3\) and 'plot' \(step 4\)"),
    "plot_into_a_later_save": (f"{LOADED} plot out/fig.png save out",
                               r"out/fig\.png: written by two steps of this command line, 'plot' and 'save'"),
    "save_and_mcap_one_path": (f"{LOADED} save run mcap run",
                               r"run: written by two steps of this command line, 'save' and 'mcap'"),
    "export_twice": ("load {good_csv} export a.csv export sub/../a.csv --overwrite",
                     r"a\.csv: written by two steps .*'export' \(step 2\) and 'export' \(step 3\)"),
    "save_through_a_dangling_link": (f"{LOADED} save {{invalid}}/links/dangling/out",
                                     r"links/dangling: a symbolic link to \.\./no-such-directory/results, which does "
                                     r"not exist; refusing to write through it"),
    "save_to_a_dangling_link": (f"{LOADED} save {{invalid}}/links/dangling",
                                r"links/dangling: a symbolic link to .*which does not exist"),
    "record_through_a_dangling_link": ("record loop:// -o {invalid}/links/dangling/rec --seconds 1",
                                       r"links/dangling: a symbolic link to .*which does not exist"),
    "export_through_a_dangling_link": ("load {good_csv} export {invalid}/links/dangling/x.csv",
                                       r"links/dangling: a symbolic link to .*which does not exist"),
    "save_to_a_link_out_of_its_directory": (f"{LOADED} save {{invalid}}/links/outward --overwrite",
                                            r"links/outward: a symbolic link to \.\./results, outside its directory; "
                                            r"refusing to write through it"),
})
for name, (args, expect) in cases.items():
    (CLI / f"{name}.yaml").write_text(yaml.safe_dump({"args": args, "expect": expect}, sort_keys=False, width=200))
print(len(cases), "cli cases")

# ---- results directories: plot RESULTS_DIR -o FIG; "expect" holds the regex
import bendsense  # noqa: E402
from bendsense.results import write_results  # noqa: E402
from bendsense.shape.pcc import reconstruct  # noqa: E402

R = ROOT / "results"
shutil.rmtree(R, ignore_errors=True)
R.mkdir()
session = bendsense.read_session_csv(good / "session.csv")
calibration = bendsense.Calibration.load(REPO / "tests" / "data" / "calibration" / "calibration_v1.yaml")
shape = reconstruct(session.signals, calibration, bendsense.load_config().sensor)
write_results(R / "_template", session, shape)
template_csv = (R / "_template" / "results.csv").read_text()
template_npz = (R / "_template" / "shape.npz").read_bytes()
shutil.rmtree(R / "_template")


def results_case(name, expect, csv=None, npz=None, drop_npz=False):
    d = R / name
    d.mkdir()
    (d / "results.csv").write_text(template_csv if csv is None else csv)
    if not drop_npz:
        (d / "shape.npz").write_bytes(template_npz if npz is None else npz)
    (d / "expect").write_text(expect + "\n")


lines = template_csv.splitlines()
results_case("npz_garbage", r"shape\.npz: not a shape\.npz of bendsense", npz=b"garbage")
results_case("npz_truncated", r"shape\.npz: not a shape\.npz of bendsense", npz=template_npz[: len(template_npz) // 2])
results_case("npz_missing", r"shape\.npz: missing \(every results directory has one\)", drop_npz=True)
results_case("csv_binary", r"results\.csv: binary data, not a results CSV", csv="t_s\x00\x01\n")
results_case("csv_empty", r"results\.csv: empty \(no header row\)", csv="")
results_case("csv_text_time", r"results\.csv: column t_s: expected numbers",
             csv="\n".join([lines[0], "noon" + lines[1][lines[1].index(","):], *lines[2:]]) + "\n")
results_case("csv_not_ours", r"results\.csv: not a results\.csv of bendsense \(no column tip_x_m\)",
             csv="t_s,ch1\n0,1\n")
results_case("csv_more_rows", r"shape\.npz: positions_m has shape \(4, \d+, 2\), expected \(5, \d+, 2\)",
             csv=template_csv + lines[-1] + "\n")
import io  # noqa: E402

buf = io.BytesIO()
np.savez(buf, s=np.zeros(3))
results_case("npz_other_arrays", r"shape\.npz: not a shape\.npz of bendsense", npz=buf.getvalue())
results_case("csv_latin1", r"results\.csv: not UTF-8 text", csv=None)
(R / "csv_latin1" / "results.csv").write_bytes(template_csv.replace("ok", "\u00f6k").encode("latin-1"))
print("results cases", len(list(R.iterdir())))
