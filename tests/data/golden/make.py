"""Write ``expected.json``: the SHA-256 of every output of recipe.py's commands (masked).

Run only when an output changes on purpose, and say why in the commit.

    python tests/data/golden/make.py
"""

import json
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from recipe import digest  # noqa: E402


def main():
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run([sys.executable, str(HERE / "recipe.py"), tmp], check=True)
        digests = digest(tmp)
    (HERE / "expected.json").write_text(json.dumps(digests, indent=1) + "\n")
    print(f"wrote the digests of {len(digests)} files to {HERE / 'expected.json'}")


if __name__ == "__main__":
    main()
