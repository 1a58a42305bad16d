"""Commands of the sim area: ``simulate`` writes the paper's experiments as simulated recordings."""

from __future__ import annotations

from pathlib import Path

import click

from bendsense import output
from bendsense.cli._common import (
    SEED,
    ContactLocation,
    Finite,
    InterspersedCommand,
    PressureKpa,
    Relative,
    config_option,
    overwrite_option,
    say,
    step_io,
)

# kept in sync with bendsense.sim.scenarios.SCENARIOS (imported lazily for a fast --help)
_SCENARIOS = ("calibration", "validation", "tip-loads", "contact", "time-varying", "free-sweep", "all")


@click.command("simulate", cls=InterspersedCommand)
@click.argument("scenario", metavar="SCENARIO", type=click.Choice(_SCENARIOS))
@click.option(
    "-o",
    "--output",
    "out_dir",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Directory to write (created; with 'all', one subdirectory per scenario).",
)
@click.option("--seed", type=SEED, default=0, show_default=True, help="Seed of the sensor hardware and the noise.")
@config_option
@click.option("--noise-counts", type=Finite(min=0), help="Sensor noise std [counts] (default 1.5).")
@click.option("--frames", type=click.IntRange(min=1),
              help="Frames per strip or configuration (default 50 / 5; free-sweep: frames of the sweep, "
                   "default 200). A scenario is simulated in memory, "
                   "one recording at a time (tip-loads: 44 configurations, ~10 kB a frame): a number whose "
                   "frames would not fit the free memory is refused before any work.")
@click.option("--ei-error", type=Relative(), help="Model mismatch: relative error of the true EI.")
@click.option("--k0-error", type=Relative(), help="Model mismatch: relative error of the true K0.")
@click.option("--base-rotation", type=Relative(), help="Model mismatch: base rotation per radian of bending [rad/rad].")
@click.option("--hysteresis-kpa", type=PressureKpa(min=0), help="Model mismatch: pressure play [kPa].")
@click.option("--max-pressure-kpa", type=PressureKpa(min=0), help="free-sweep: peak pressure [kPa] (default 120).")
@click.option("--contact-n", type=Finite(min=0),
              help="free-sweep: a contact force [N] over the middle fifth of the way down (default 0); "
                   "time-varying: the contact force while on (default 0.15).")
@click.option("--contact-s-m", "contact_s_m", type=ContactLocation(),
              help="contact, time-varying: the contact force acts at this arc length s_c [m] along the body "
                   "(0 < s_c <= L), normal to the loaded tangent there; truth column contact_s_m. time-varying "
                   "also takes 'along-body': each touch lands somewhere else along the body.")
@click.option("--rate", "rate_hz", type=Finite(min=0, min_open=True),
              help="Frame rate [Hz] of the recordings (default 35; time-varying 100).")
@overwrite_option
def simulate(
    scenario,
    out_dir,
    seed,
    config_path,
    noise_counts,
    frames,
    ei_error,
    k0_error,
    base_rotation,
    hysteresis_kpa,
    max_pressure_kpa,
    contact_n,
    contact_s_m,
    rate_hz,
    overwrite,
):
    """Write SCENARIO as simulated session CSVs with ground-truth columns.

    SCENARIO is one of the paper's experiments: calibration (flat + strips, with a
    manifest for 'bendsense calibrate'), validation (strips of known curvature),
    tip-loads (20-120 kPa x 0-0.3 N), contact (12 random normal contact forces, at the
    tip or, with --contact-s-m, along the body),
    time-varying (10 s at 100 Hz), free-sweep (a free pressure ramp 0 -> max -> 0, for
    'bendsense identify free-bending --session'), or all.
    """
    options = {
        "noise_counts": noise_counts,
        "ei_error": ei_error,
        "k0_error": k0_error,
        "base_rotation_rad_per_rad": base_rotation,
        "hysteresis_pa": None if hysteresis_kpa is None else hysteresis_kpa * 1e3,
        "pressure_max_pa": None if max_pressure_kpa is None else max_pressure_kpa * 1e3,
        "contact_n": contact_n,
        "contact_s_m": contact_s_m,
        "rate_hz": rate_hz,
    }
    for flag, value, allowed in (("--max-pressure-kpa", max_pressure_kpa, ("free-sweep", "all")),
                                 ("--contact-n", contact_n, ("free-sweep", "time-varying", "all")),
                                 ("--contact-s-m", contact_s_m, ("contact", "time-varying", "all"))):
        if value is not None and scenario not in allowed:
            raise click.BadParameter(f"applies to {', '.join(allowed[:-1])} only, not {scenario}", param_hint=flag)
    if contact_s_m == "along-body" and scenario != "time-varying":
        raise click.BadParameter(f"'along-body' applies to time-varying only, not {scenario}; give s_c [m]",
                                 param_hint="--contact-s-m")
    if frames is not None:
        if scenario in ("calibration", "validation", "all"):
            options["frames_per_strip"] = frames
        if scenario in ("tip-loads", "contact", "all"):
            options["frames_per_config"] = frames
        if scenario in ("free-sweep", "all"):
            options["n_frames"] = max(frames, 2)
    options = {k: v for k, v in options.items() if v is not None}
    if frames is not None:
        from bendsense.sim.scenarios import check_memory

        check_memory(scenario, options, field="--frames")  # before any work (the group makes it one line)

    def step(state):
        from bendsense.sim.scenarios import _simulate

        _, summaries = _simulate(scenario, out_dir, config_path, seed, overwrite=overwrite, **options)
        for name, summary in summaries.items():
            excluded = summary["excluded_frames"]
            note = f", {excluded} excluded (beam solve failed)" if excluded else ""
            say(
                f"{name}: wrote {len(summary['files'])} files, {summary['frames']} frames{note} to {summary['path']}"
            )
        return state

    return step_io(step, outputs=[output.directory(out_dir, overwrite=overwrite)], inputs=[config_path])


COMMANDS = [simulate]
