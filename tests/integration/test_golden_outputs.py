"""Every file the frozen recipe writes is byte for byte what it was (tests/data/golden/recipe.py).

Sessions, a calibration, two configs, results.csv and shape.npz of three chains, an MCAP
file and an exported session: a change of any output, whatever the code's layout, fails
here. Dates and paths a file records about its own making are masked.
"""

import json
import subprocess
import sys
from pathlib import Path

GOLDEN = Path(__file__).parents[1] / "data" / "golden"
sys.path.insert(0, str(GOLDEN))

from recipe import digest, masked  # noqa: E402


def test_the_recipe_writes_the_frozen_files_byte_for_byte(tmp_path):
    subprocess.run([sys.executable, str(GOLDEN / "recipe.py"), str(tmp_path)], check=True)
    expected = json.loads((GOLDEN / "expected.json").read_text())
    written = digest(tmp_path)
    assert sorted(written) == sorted(expected)
    assert [name for name in expected if written[name] != expected[name]] == []


def test_the_mask_hides_only_a_files_record_of_its_making():
    line = b"# identified by bendsense from /home/lab/run-3/free_sweep.csv (2026-11-29T01:02:03.5Z)"
    assert masked(line) == b"# identified by bendsense from <masked>free_sweep.csv (<masked>)"
    assert masked(b"source: 'adapt 2026-11-29 02:34 UTC from free_sweep") == b"source: 'adapt <masked> from free_sweep"
    assert masked(b"1.25,0.0123,2026.5,nan\n") == b"1.25,0.0123,2026.5,nan\n"
