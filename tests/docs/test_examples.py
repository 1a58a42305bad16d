"""Every script in examples/ runs as a script: exit code 0 and the figures it promises.

Each example takes ``--out DIR`` and writes its figures there; it is run in a
subprocess (as a user would run it), with a temporary output directory and the Agg
backend, from a temporary working directory so that it cannot depend on files of the
repository's root.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
SCRIPTS = sorted(EXAMPLES.glob("*.py"))
# figures (and other files) each example must write into --out
EXPECTED = {
    "full_workflow.py": ["calibration.png", "shapes.png", "force.png", "summary.png", "calibration.yaml",
                         "results/results.csv", "results/shape.npz"],
    "beam_solver.py": ["beam_vs_elastica.png"],
    "custom_sensor.py": ["custom_sensor_shapes.png", "my_sensor.yaml", "my_calibration.yaml"],
}


def test_every_example_is_listed():
    assert sorted(p.name for p in SCRIPTS) == sorted(EXPECTED)


@pytest.mark.parametrize("script", SCRIPTS, ids=[p.name for p in SCRIPTS])
def test_example_runs_and_writes_its_figures(script: Path, tmp_path: Path):
    out = tmp_path / "out"
    env = dict(os.environ, MPLBACKEND="Agg")
    proc = subprocess.run(
        [sys.executable, str(script), "--out", str(out)],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL,
    )
    assert proc.returncode == 0, f"{script.name} exited {proc.returncode}\n{proc.stdout[-2000:]}\n{proc.stderr[-3000:]}"
    for name in EXPECTED.get(script.name, []):
        path = out / name
        assert path.is_file() and path.stat().st_size > 0, f"{script.name}: did not write {name}"
    for png in out.rglob("*.png"):
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", png
    assert "Traceback" not in proc.stderr


def test_example_without_out_writes_into_a_temporary_directory(tmp_path: Path):
    # the default --out is a fresh temporary directory, never the working directory
    env = dict(os.environ, MPLBACKEND="Agg")
    proc = subprocess.run(
        [sys.executable, str(EXAMPLES / "beam_solver.py")],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert list(tmp_path.iterdir()) == []
    written = Path(proc.stdout.strip().splitlines()[-1].removeprefix("wrote "))
    assert written.is_file()
    written.unlink()
    written.parent.rmdir()
