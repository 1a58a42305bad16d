"""The frozen fixtures' outputs: one recipe of bendsense commands, run by make.py and the test.

``python tests/data/golden/make.py`` runs :data:`COMMANDS` and writes the SHA-256 of each
output to ``expected.json``; ``tests/test_golden_outputs.py`` runs them again into a
temporary directory and compares every file's digest, so every byte. Both run it in a
fresh interpreter: a least-squares fit's last bits can follow the process's history (the
memory alignment of numpy's sums), and a fresh process is the run a user makes. They cover what a lab's files hold: simulated session
CSVs, a calibration, a config identified from a session and one adapted by the chain,
results.csv and shape.npz (tip loads, a contact along the body, a track), an MCAP file,
and a session CSV exported from the frozen native session.

Only what a file states about its own making may differ between runs, and is masked:
the date and the paths in a config's provenance comment (:func:`masked`).
"""

from __future__ import annotations

import hashlib
import re
import shlex
from pathlib import Path

from click.testing import CliRunner

FORMATS = Path(__file__).resolve().parent.parent / "formats"

COMMANDS = [
    "simulate calibration --frames 8 --seed 3 -o {w}/cal",
    "calibrate {w}/cal/manifest.yaml -o {w}/calibration.yaml",
    "simulate free-sweep --seed 3 --frames 120 -o {w}/sweep",
    "simulate time-varying --seed 3 -o {w}/tv",
    "simulate contact --seed 3 --contact-s-m 0.05 -o {w}/contact",
    "identify free-bending --session {w}/sweep/free_sweep.csv --calibration {w}/calibration.yaml -o {w}/identified.yaml",
    "load {w}/sweep/free_sweep.csv --calibration {w}/calibration.yaml reconstruct adapt estimate save {w}/adapted",
    "load {w}/tv/session.csv --calibration {w}/calibration.yaml reconstruct estimate --constraint normal track"
    " save {w}/tracked mcap {w}/tracked.mcap",
    "load {w}/contact/contact.csv --calibration {w}/calibration.yaml reconstruct estimate --load contact save {w}/contact_out",
    f"load {FORMATS}/session_v2 export {{w}}/session_v2.csv",
]

# a file's own record of where and when it was made
_VOLATILE = re.compile(rb"(\d{4}-\d\d-\d\d[T ][\d:.]+(?: UTC|Z)?|/[^\s'\"]*/(?=[\w.-]+(yaml|csv|bsess)\b))")


def run(workdir) -> None:
    """Run :data:`COMMANDS` into ``workdir``."""
    from bendsense.cli import main

    workdir = Path(workdir)
    runner = CliRunner()
    for command in COMMANDS:
        result = runner.invoke(main, shlex.split(command.format(w=workdir)), catch_exceptions=False)
        if result.exit_code != 0:
            raise RuntimeError(f"{command}: exit {result.exit_code}\n{result.output}")


def digest(workdir) -> dict:
    """The SHA-256 of every file under ``workdir``, masked (:func:`masked`), by its relative path."""
    workdir = Path(workdir)
    return {p.relative_to(workdir).as_posix(): hashlib.sha256(masked(p.read_bytes())).hexdigest()
            for p in sorted(workdir.rglob("*")) if p.is_file()}


def masked(data: bytes) -> bytes:
    """``data`` with dates and directory paths (a file's own record of its making) masked."""
    return _VOLATILE.sub(b"<masked>", data)


if __name__ == "__main__":
    import sys

    run(sys.argv[1])
