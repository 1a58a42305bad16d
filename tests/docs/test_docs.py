"""The documentation runs: every fenced ``bash`` and ``python`` block of README.md and docs/*.md.

The blocks of one page run in order, in one fresh temporary working directory that
holds copies of the repository's ``configs/`` and ``examples/`` (the docs are written
to run from the repository root), so later blocks see the files earlier ones wrote.
``bash`` blocks run as under ``bash -euo pipefail``, ``python`` blocks with this
interpreter; each must exit 0. Blocks in other languages (``text``, ``yaml``, …) are
not run.

A page's Python runs in one interpreter of its own (tests/docs/page_interpreter.py), in
the page's directory, where a Python call does what the process would: its ``python``
blocks, and in a ``bash`` block without shell state (no variables, background jobs,
here-documents or ``cd``) each plain ``bendsense ARGS`` command (the command line's entry
point called there), ``python -c "CODE"`` and ``python SCRIPT ARGS`` (not the benchmarks:
they time a fresh interpreter); that block's other commands run one by one under
``bash -euo pipefail``, and a block with shell state runs whole under bash, as before.
The interpreter starts once and loads the compiled kernels once per page, where each
command was a process of its own (~1 s of CPU each). ``bendsense demo``, the first block
of two pages on the same fresh directory, runs once: the other page takes its output and
its files. Three pages run at a time, each in its own directory; a block that times a board
against its client (a simulated board, a recording, a control loop, a benchmark) waits
until it is alone and runs alone.

What is not run as written:

- a command on the line after a ``# needs hardware`` comment (with its ``\\``
  continuation lines) needs a sensor board and is skipped;
- ``pip install ... && CMD``: the package is already installed in the test
  environment, so only ``CMD`` runs; ``python -m pytest`` is skipped (the suite would
  run itself recursively);
- ``bendsense reproduce`` runs with its documented ``--quick`` flag (the full run takes
  minutes; the quick one makes every table and figure);
- ``python benchmarks/...`` (docs/performance.md) runs with its ``--quick`` flag
  (a few seconds: every row, fewer repetitions).

Example output is checked, not pasted: a ``text`` block right after an
``<!-- output -->`` line (an HTML comment, invisible on the rendered site) is the
output of the nearest runnable block above it, and that block's fenced neighbour
above the marker must be that runnable block (or another output block of it). Every
non-empty line of the documented output must appear as a line of the block's real
stdout + stderr, after masking what legitimately differs between runs (rates
``4,618 frames/s``, durations ``in 115.4 s`` or ``, 10 s``, ISO time stamps,
``/dev/pts/N``, temporary paths); everything else must match exactly. A line ``...`` abridges (it is not
compared) and a line ending in `` ...`` matches the lines that start with the text
before it.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import select
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
COPIED = ("configs", "examples", "benchmarks", "tools")
# and the independent forward model that tools/model_error.py (so benchmarks/bench_model_error.py) builds on
COPIED_FILES = ("tests/forward_model.py",)
HARDWARE = re.compile(r"^\s*#\s*needs hardware\b", re.IGNORECASE)
FENCE = re.compile(r"^(?P<indent>[ \t]*)```(?P<lang>[\w+-]*)[^\n]*\n(?P<body>.*?)^(?P=indent)```[ \t]*$", re.M | re.S)
TIMEOUT_S = 300
OUTPUT_MARK = re.compile(r"^[ \t]*<!--\s*output\s*-->[ \t]*\n[ \t]*\Z")


def extract_steps(text: str) -> list[tuple[str, str, list[str]]]:
    """``(language, code, outputs)`` of every fenced bash or python block, in page order.

    ``outputs`` are the bodies of the ``<!-- output -->`` text blocks that document
    what the block prints. A marked output block whose fenced neighbour above is
    neither a runnable block nor another output block of one is an error (its
    command would not be run, so its output could not be checked).
    """
    out: list[tuple[str, str, list[str]]] = []
    previous = None  # what the last fenced block was: "run", "output" or "other"
    for m in FENCE.finditer(text):
        lang = m["lang"].lower()
        line_start = text.rfind("\n", 0, max(m.start() - 1, 0)) + 1 if m.start() else 0
        marked = bool(OUTPUT_MARK.match(text[line_start:m.start()]))
        if marked:
            if lang != "text" or previous not in ("run", "output"):
                line = text.count("\n", 0, m.start()) + 1
                raise ValueError(f"line {line}: an <!-- output --> block must be a text block after a runnable "
                                 f"block (bash or python, not only hardware commands)")
            out[-1][2].append(m["body"])
            previous = "output"
            continue
        previous = "other"
        if lang in ("bash", "sh", "shell"):
            code = runnable_shell(m["body"])
            if code.strip():
                out.append(("bash", code, []))
                previous = "run"
        elif lang == "python":
            out.append(("python", m["body"], []))
            previous = "run"
    return out


def extract_blocks(text: str) -> list[tuple[str, str]]:
    """The ``(language, code)`` of every fenced bash or python block, in page order."""
    return [(lang, code) for lang, code, _ in extract_steps(text)]


# what differs between two runs of the same command: (pattern, replacement)
VARYING = [
    (re.compile(r"\d[\d,]*(?:\.\d+)?(?= frames/s\b)"), "<RATE>"),
    (re.compile(r"(?<=\bin )\d+(?:\.\d+)?(?= (?:s|ms|min)\b)"), "<DURATION>"),
    (re.compile(r"(?<=, )\d+(?:\.\d+)?(?= s\b)"), "<DURATION>"),
    (re.compile(r"\b\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(?:\.\d+)?(?:Z|[+-]\d\d:?\d\d)?"), "<TIME>"),
    (re.compile(r"/dev/pts/\d+"), "/dev/pts/<N>"),
    (re.compile(r"(?:/private)?(?:/tmp|/var/folders|" + re.escape(tempfile.gettempdir()) + r")/[^\s'\"),:;]*"),
     "<TMP>"),
]


def mask(line: str) -> str:
    """``line`` with what legitimately varies between runs replaced by placeholders."""
    for pattern, placeholder in VARYING:
        line = pattern.sub(placeholder, line)
    return line.rstrip()


_SECONDS = {"ms": 1e-3, "s": 1.0, "min": 60.0}
_DURATIONS = re.compile(r"(?:(?<=\bin )|(?<=, ))(\d+(?:\.\d+)?) (ms|s|min)\b")


def stale_duration(documented: str, actual: str) -> bool:
    """Whether a duration the page states is 3× (and 10 s) off what the same run took here: stale on any machine.

    Durations are masked to match the output at all (machines differ by ±25 %, a cold
    cache by a minute); a page that says "in 192.2 s" of a command that now takes 60 s
    is out of date all the same.
    """
    pairs = zip((float(v) * _SECONDS[u] for v, u in _DURATIONS.findall(documented)),
                (float(v) * _SECONDS[u] for v, u in _DURATIONS.findall(actual)))
    return any(d > 3.0 * a + 10.0 or a > 3.0 * d + 10.0 for d, a in pairs)


def missing_output(documented: str, actual: str) -> list[str]:
    """The documented lines (masked) that are not lines of ``actual`` (masked), or state a stale duration."""
    lines = actual.splitlines()
    real = [mask(line) for line in lines]
    missing = []
    for line in documented.splitlines():
        if not line.strip() or line.strip() in ("...", "…"):
            continue
        want = mask(line)
        if want.endswith(" ..."):
            prefix = want[:-len(" ...")]
            found = any(r.startswith(prefix) for r in real)
        else:
            same = [raw for raw, r in zip(lines, real) if r == want]
            found = bool(same)
            if found and all(stale_duration(line, raw) for raw in same):
                missing.append(f"{line.strip()} (stale: this run printed {same[0].strip()!r})")
                continue
        if not found:
            missing.append(want)
    return missing


def runnable_shell(code: str) -> str:
    """``code`` without its hardware commands, with the ``pip install`` and reproduce rules applied."""
    lines = code.splitlines()
    kept = []
    i = 0
    while i < len(lines):
        line = lines[i]
        if HARDWARE.match(line):
            # skip the marked command and its continuation lines
            i += 1
            while i < len(lines) and lines[i].rstrip().endswith("\\"):
                i += 1
            i += 1
            continue
        kept.append(_test_equivalent(line))
        i += 1
    return "\n".join(kept) + "\n"


def _test_equivalent(line: str) -> str:
    stripped = line.strip()
    if stripped.startswith("pip install"):
        parts = [p.strip() for p in stripped.split("&&")]
        rest = [p for p in parts if not p.startswith("pip install")]
        rest = [p for p in rest if not re.match(r"python[0-9.]* -m pytest\b", p)]
        return " && ".join(rest)
    command = stripped.split("#", 1)[0]  # a "--quick" in the comment is no flag
    if re.match(r"bendsense\s+reproduce\b", stripped) and "--quick" not in command:
        return line.replace("reproduce", "reproduce --quick", 1)
    if re.match(r"python[0-9.]*\s+benchmarks/", stripped) and "--quick" not in command:
        return re.sub(r"(benchmarks/\S+)", r"\1 --quick", line, count=1)
    return line


# ------------------------------------------------------------------ the extraction itself


def test_hardware_commands_are_skipped_with_their_continuations():
    text = (
        "```bash\n"
        "echo one\n"
        "# needs hardware\n"
        "bendsense record /dev/ttyACM0 \\\n"
        "    -o s --seconds 3\n"
        "echo two\n"
        "```\n"
    )
    [(lang, code)] = extract_blocks(text)
    assert lang == "bash"
    assert code.split() == ["echo", "one", "echo", "two"]


def test_block_of_hardware_commands_only_is_dropped():
    text = "```bash\n# needs hardware\nbendsense live /dev/ttyACM0 --calibration cal.yaml\n```\n"
    assert extract_blocks(text) == []


def test_pip_install_lines_keep_only_the_command_after_them():
    assert _test_equivalent("pip install . && bendsense demo") == "bendsense demo"
    assert _test_equivalent('pip install ".[test,distributed]" && python -m pytest') == ""
    assert _test_equivalent('pip install ".[distributed]"') == ""


def test_reproduce_gets_its_quick_flag():
    assert _test_equivalent("bendsense reproduce -o report") == "bendsense reproduce --quick -o report"
    assert _test_equivalent("bendsense reproduce --quick -o r") == "bendsense reproduce --quick -o r"


def test_benchmarks_get_their_quick_flag():
    line = "python benchmarks/run_all.py --markdown results.md   # ~10 s"
    assert _test_equivalent(line).startswith("python benchmarks/run_all.py --quick --markdown results.md")
    # a "--quick" mentioned in the comment does not count as the flag
    commented = "python benchmarks/bench_batch.py   # ~2 min; --no-dask, --quick"
    assert _test_equivalent(commented).startswith("python benchmarks/bench_batch.py --quick")


def test_other_languages_are_not_run_and_order_is_kept():
    text = "```text\nnot run\n```\n```python\nprint(1)\n```\n```yaml\na: 1\n```\n```bash\necho 2\n```\n"
    assert extract_blocks(text) == [("python", "print(1)\n"), ("bash", "echo 2\n")]


def test_output_blocks_belong_to_the_runnable_block_above():
    text = (
        "```bash\necho one\n```\n\nIt prints:\n\n<!-- output -->\n```text\none\n```\n"
        "```text\nnot output\n```\n```python\nprint(2)\n```\n<!-- output -->\n```text\n2\n```\n"
        "<!-- output -->\n```text\n2 again\n```\n"
    )
    assert extract_steps(text) == [("bash", "echo one\n", ["one\n"]), ("python", "print(2)\n", ["2\n", "2 again\n"])]


def test_output_block_after_no_runnable_block_is_an_error():
    after_text = "```bash\necho 1\n```\n```text\nx\n```\n<!-- output -->\n```text\n1\n```\n"
    after_hardware = ("```bash\n# needs hardware\nbendsense record /dev/ttyACM0 -o s\n```\n"
                      "<!-- output -->\n```text\n1\n```\n")
    first = "<!-- output -->\n```text\n1\n```\n"
    not_text = "```bash\necho 1\n```\n<!-- output -->\n```yaml\na: 1\n```\n"
    for text in (after_text, after_hardware, first, not_text):
        with pytest.raises(ValueError, match="output"):
            extract_steps(text)


def test_an_unmarked_text_block_is_no_output():
    # the marker must be the line right before the fence
    text = "```bash\necho 1\n```\n<!-- output -->\n\n```text\n2\n```\n"
    assert extract_steps(text) == [("bash", "echo 1\n", [])]


def test_masking_hides_rates_durations_terminals_and_temporary_paths():
    assert mask("  constraint none  RMS error 0.1421 N, converged 100 %, 4,618 frames/s") == (
        "  constraint none  RMS error 0.1421 N, converged 100 %, <RATE> frames/s")
    assert mask("processed 500 frames in 115.4 s") == "processed 500 frames in <DURATION> s"
    assert mask("compiling: 7/12 functions, 20 s (continuation)") == (
        "compiling: 7/12 functions, <DURATION> s (continuation)")
    assert mask("board on /dev/pts/7") == "board on /dev/pts/<N>"
    assert mask("2026-11-21T11:06:14.082922Z crc: 1 CRC error(s)") == "<TIME> crc: 1 CRC error(s)"
    assert mask(f"wrote {Path(tempfile.gettempdir(), 'pytest-of-x', 'test_a0', 'results.csv')}") == "wrote <TMP>"
    assert mask("wrote results/results.csv") == "wrote results/results.csv"
    # what does not vary is kept: errors, coverages, counts, seeded numbers
    kept = "force vs simulated truth (500 frames, peak contact force 0.15 N): RMS error 0.0039 N, 84 %"
    assert mask(kept) == kept


def test_documented_output_must_match_the_real_output():
    actual = "noise\n  constraint normal  RMS error 0.0041 N, 3,120 frames/s\nError: x.csv: line 2: bad\n"
    assert missing_output("  constraint normal  RMS error 0.0041 N, 4,618 frames/s\n", actual) == []
    # a changed deterministic number is caught, as is a missing line or a changed indentation
    assert missing_output("  constraint normal  RMS error 0.0039 N, 4,618 frames/s\n", actual) == [
        "  constraint normal  RMS error 0.0039 N, <RATE> frames/s"]
    assert missing_output("Error: x.csv: line 3: bad\n", actual) == ["Error: x.csv: line 3: bad"]
    assert missing_output("constraint normal  RMS error 0.0041 N, 1 frames/s\n", actual) != []
    # "..." abridges: a line of its own is skipped, a trailing one matches a prefix
    assert missing_output("...\nError: x.csv: line 2: ...\n\n", actual) == []
    assert missing_output("Error: y.csv: ...\n", actual) == ["Error: y.csv: ..."]


def test_a_stale_duration_is_caught():
    actual = "wrote demo/session, demo/results in 48.9 s\nprocessed 500 frames in 0.85 s\n"
    assert missing_output("wrote demo/session, demo/results in 61.0 s\n", actual) == []  # another machine
    assert missing_output("processed 500 frames in 0.4 s\n", actual) == []
    stale = missing_output("wrote demo/session, demo/results in 192.2 s\n", actual)
    assert len(stale) == 1 and "stale" in stale[0] and "48.9 s" in stale[0]
    assert missing_output("processed 500 frames in 40 s\n", actual) != []
    assert stale_duration("in 5 s", "in 12 s") is False  # short runs: within the 10 s slack


def test_fences_name_their_language_without_a_space():
    # a page whose fences were mistyped (e.g. ``` bash) would silently run nothing
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        assert "``` bash" not in text and "```Bash" not in text, page.name


# ------------------------------------------------------------------ what runs in the page's interpreter

# a block with shell state runs whole under bash: variables ($VAR, $!), background jobs, here-documents, cd, ...
_STATEFUL_WORDS = {"cd", "pushd", "popd", "export", "unset", "set", "source", ".", "alias", "function", "if", "for",
                   "while", "until", "case", "{", "(", "trap", "wait", "kill", "read", "shopt", "exec", "eval"}
_ASSIGNMENT = re.compile(r"^[A-Za-z_][A-Za-z_0-9]*=")
_SHELL_CHARS = set("$`*?[]{}~\\'\"")  # expansions, globs, quoting left over: bash's business
_PYTHON_C = re.compile(r'python3?\s+-c\s+"([^"$`\\]*)"\s*', re.S)


def _commands(code: str) -> list[str] | None:
    """The commands of a bash block (continuation lines and multi-line quotes joined), or None if it cannot be
    split into commands that run one after the other (a line shlex cannot read)."""
    commands, pending = [], ""
    for line in code.splitlines():
        pending += line + "\n"
        if pending.rstrip("\n").endswith("\\"):
            continue
        try:
            words = shlex.split(pending, comments=True)
        except ValueError:  # an open quote: the command goes on
            continue
        if words:
            commands.append(pending.rstrip("\n"))
        pending = ""
    return None if pending.strip() else commands


def _words(command: str) -> list[str]:
    lexer = shlex.shlex(command.replace("\\\n", " "), posix=True, punctuation_chars=True)  # continuation lines
    lexer.whitespace_split = True
    return list(lexer)


def in_process_steps(lang: str, code: str) -> list[tuple[str, object]]:
    """How a block runs: ``(kind, what)`` steps one after the other, each must exit 0.

    ``("python", CODE)``, ``("cli", ARGS)`` and ``("script", ARGV)`` run in the page's
    interpreter, ``("bash", TEXT)`` under ``bash -euo pipefail``. A bash block with shell
    state is one bash step.
    """
    if lang == "python":
        return [("python", code)]
    whole = [("bash", code)]
    commands = _commands(code) if "<<" not in code else None
    if commands is None:
        return whole
    steps = []
    for command in commands:
        words = _words(command)
        if "$" in command or words[0] in _STATEFUL_WORDS or "&" in words or (
                _ASSIGNMENT.match(words[0]) and all(_ASSIGNMENT.match(w) for w in words)):
            return whole
        plain = not any(set(w) <= set("();<>|&") for w in words) and not any(set(w) & _SHELL_CHARS for w in words)
        python_c = _PYTHON_C.fullmatch(command.strip())
        if plain and words[0] == "bendsense":
            steps.append(("cli", words[1:]))
        elif python_c:
            steps.append(("python", python_c[1]))
        elif plain and words[0] in ("python", "python3") and len(words) > 1 and words[1].endswith(".py") and \
                not words[1].startswith("benchmarks/"):
            steps.append(("script", words[1:]))
        else:
            steps.append(("bash", command))
    return steps


def test_plain_commands_run_in_process_and_the_rest_under_bash():
    code = ("bendsense simulate calibration -o sim/cal   # or record your own (strips)\n"
            "bendsense load a.csv --calibration cal.yaml \\\n    reconstruct estimate --contact-s-m thumb=0.10\n"
            "head -n 3 out/tv/results.csv | cut -c 1-200\n"
            "python examples/full_workflow.py --out figures\n"
            "python benchmarks/run_all.py --quick\n"
            'python -c "\nimport numpy as np\nprint(np.pi)\n"\n'
            "bendsense load board.csv reconstruct 2>&1 || true\n"
            "OPENBLAS_NUM_THREADS=1 python examples/beam_solver.py --out beam-figures\n"
            "ls sim/*.csv\n")
    assert in_process_steps("bash", code) == [
        ("cli", ["simulate", "calibration", "-o", "sim/cal"]),
        ("cli", ["load", "a.csv", "--calibration", "cal.yaml", "reconstruct", "estimate", "--contact-s-m",
                 "thumb=0.10"]),
        ("bash", "head -n 3 out/tv/results.csv | cut -c 1-200"),
        ("script", ["examples/full_workflow.py", "--out", "figures"]),
        ("bash", "python benchmarks/run_all.py --quick"),
        ("python", "\nimport numpy as np\nprint(np.pi)\n"),
        ("bash", "bendsense load board.csv reconstruct 2>&1 || true"),
        ("bash", "OPENBLAS_NUM_THREADS=1 python examples/beam_solver.py --out beam-figures"),
        ("bash", "ls sim/*.csv"),
    ]
    assert in_process_steps("python", "print(1)\n") == [("python", "print(1)\n")]


@pytest.mark.parametrize("code", [
    "rm -f port.txt\nbendsense sim-device > port.txt &\nbendsense record \"$(cat port.txt)\" -o r\nkill $!\n",
    "cat > a.csv <<'EOF'\nx,y\n1,2\nEOF\nbendsense identify free-bending a.csv -o c.yaml\n",
    "cd sim\nbendsense simulate calibration -o cal\n",
    "X=1\nbendsense demo\n",
    'python -c "print(\'$HOME\')"\n',
])
def test_a_block_with_shell_state_runs_whole_under_bash(code):
    assert in_process_steps("bash", code) == [("bash", code)]


# ------------------------------------------------------------------ running the pages


def _spawn(cmd: list[str], cwd: Path, env: dict, out, err, timeout: float) -> int | None:
    """Run ``cmd`` in its own process group, output to the files ``out`` and ``err``; afterwards end whatever it
    left running. Its exit status, None if it timed out.

    Output goes to files, not pipes, so that a background job the command started (a
    simulated board) cannot keep the call waiting after the command has finished or failed.
    """
    proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=out, stderr=err, stdin=subprocess.DEVNULL,
                            start_new_session=True)
    try:
        return proc.wait(timeout=max(timeout, 0.0))
    except subprocess.TimeoutExpired:
        return None
    finally:
        try:
            os.killpg(proc.pid, signal.SIGTERM)
        except ProcessLookupError:
            pass
        proc.wait()


def _run(lang: str, code: str, cwd: Path, env: dict) -> subprocess.CompletedProcess:
    """Run one block as a process of its own (bash, or this Python for a ``python`` block)."""
    cmd = ["bash", "-euo", "pipefail", "-c", code] if lang == "bash" else [sys.executable, "-c", code]
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        returncode = _spawn(cmd, cwd, env, out, err, TIMEOUT_S)
        out.seek(0)
        err.seek(0)
        stderr = err.read() + (f"\n[timed out after {TIMEOUT_S} s]" if returncode is None else "")
        return subprocess.CompletedProcess(cmd, -1 if returncode is None else returncode, out.read(), stderr)


INTERPRETER = Path(__file__).with_name("page_interpreter.py")


class _Interpreter:
    """The page's Python interpreter (tests/docs/page_interpreter.py), in its own process group, started when a
    step first needs it."""

    def __init__(self, cwd: Path, env: dict):
        self.cwd, self.env, self.proc = cwd, env, None
        self.log = cwd.parent / f"{cwd.name}-interpreter.log"  # its own errors, outside the page's directory

    def run(self, request: dict, timeout: float) -> int | None:
        """The exit status of one step (None: timed out, the interpreter is ended)."""
        if self.proc is None:
            with open(self.log, "a", encoding="utf-8") as log:
                self.proc = subprocess.Popen([sys.executable, str(INTERPRETER)], cwd=self.cwd, env=self.env,
                                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log, text=True,
                                             start_new_session=True)
        self.proc.stdin.write(json.dumps(request) + "\n")
        self.proc.stdin.flush()
        ready, _, _ = select.select([self.proc.stdout], [], [], max(timeout, 0.0))
        reply = self.proc.stdout.readline() if ready else None
        if not reply:
            self.close(wait_s=0.0)
            if reply is not None:  # it died: what it said
                with open(request["stderr"], "a", encoding="utf-8") as err:
                    err.write(f"\n[the page's interpreter died]\n{self.log.read_text(encoding='utf-8')[-3000:]}")
                return -1
            return None
        return json.loads(reply)["returncode"]

    def close(self, wait_s: float = 10.0):
        """End it (at the end of its input, or killed after ``wait_s``), and whatever its steps left running."""
        if self.proc is None:
            return
        self.proc.stdin.close()
        try:
            self.proc.wait(timeout=wait_s)
        except subprocess.TimeoutExpired:
            pass
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.proc.wait()
        self.proc.stdout.close()
        self.proc = None


def _run_block(lang: str, code: str, cwd: Path, env: dict, interpreter: _Interpreter) -> subprocess.CompletedProcess:
    """Run one block as its steps (:func:`in_process_steps`): the first that fails ends it, as under ``bash -e``."""
    deadline = time.monotonic() + TIMEOUT_S
    with tempfile.TemporaryDirectory() as tmp:
        paths = {"stdout": str(Path(tmp, "stdout")), "stderr": str(Path(tmp, "stderr"))}
        for path in paths.values():
            Path(path).touch()
        returncode = 0
        for kind, what in in_process_steps(lang, code):
            if kind == "bash":
                with open(paths["stdout"], "a") as out, open(paths["stderr"], "a") as err:
                    returncode = _spawn(["bash", "-euo", "pipefail", "-c", what], cwd, env, out, err,
                                        deadline - time.monotonic())
            else:
                returncode = interpreter.run({kind: what, **paths}, deadline - time.monotonic())
            if returncode != 0:
                break
        stdout = Path(paths["stdout"]).read_text(encoding="utf-8", errors="replace")
        stderr = Path(paths["stderr"]).read_text(encoding="utf-8", errors="replace")
    if returncode is None:
        stderr += f"\n[timed out after {TIMEOUT_S} s]"
    return subprocess.CompletedProcess(code, -1 if returncode is None else returncode, stdout, stderr)


def test_steps_in_the_page_interpreter_exit_as_their_process_would(tmp_path: Path):
    env = dict(os.environ, MPLBACKEND="Agg")
    interpreter = _Interpreter(tmp_path, env)
    try:
        ok = _run_block("bash", "bendsense --version\necho shell > shell.txt\nbendsense -q devices\n", tmp_path, env,
                        interpreter)
        assert ok.returncode == 0 and "bendsense, version" in ok.stdout
        assert (tmp_path / "shell.txt").read_text() == "shell\n"
        # a usage error: its exit status and one line; the block's later commands do not run
        usage = _run_block("bash", "bendsense simulate calibration --frames x\ntouch after\n", tmp_path, env,
                           interpreter)
        assert usage.returncode == 2 and usage.stderr.startswith("Error: Invalid value for '--frames'")
        assert not (tmp_path / "after").exists()
        # python: an uncaught exception is its traceback and 1, sys.exit its code; each block in a fresh namespace
        crash = _run_block("python", "import os\nx = 1\nprint('before')\nraise RuntimeError('boom')\n", tmp_path,
                           env, interpreter)
        assert crash.returncode == 1 and crash.stdout == "before\n"
        assert "Traceback" in crash.stderr and crash.stderr.rstrip().endswith("RuntimeError: boom")
        fresh = _run_block("python", "import sys\nprint('x' in globals(), sys.argv)\nsys.exit(3)\n", tmp_path, env,
                           interpreter)
        assert fresh.returncode == 3 and fresh.stdout == "False ['-c']\n"
        # what a step changes for the process is put back: working directory, environment, numpy's print options
        _run_block("python", "import os, numpy as np\nos.chdir('/')\nos.environ['DOCS_X'] = '1'\n"
                             "np.set_printoptions(precision=2)\n", tmp_path, env, interpreter)
        back = _run_block("python", "import os, numpy as np\nprint(os.getcwd(), 'DOCS_X' in os.environ, np.pi * "
                                    "np.ones(1))\n", tmp_path, env, interpreter)
        assert back.stdout == f"{tmp_path} False [3.14159265]\n"
    finally:
        interpreter.close()


def test_a_step_that_hangs_times_out_and_its_interpreter_is_ended(tmp_path: Path, monkeypatch):
    monkeypatch.setattr(sys.modules[__name__], "TIMEOUT_S", 1.0)
    interpreter = _Interpreter(tmp_path, dict(os.environ))
    try:
        proc = _run_block("python", "import time\nprint('started', flush=True)\ntime.sleep(60)\n", tmp_path,
                          dict(os.environ), interpreter)
        assert proc.returncode == -1 and proc.stdout == "started\n" and "[timed out after 1.0 s]" in proc.stderr
        assert interpreter.proc is None
    finally:
        interpreter.close()


# pages without a bash or python block (theory.md) have nothing to run
RUNNABLE = [p for p in PAGES if extract_blocks(p.read_text(encoding="utf-8"))]


def test_the_pages_with_commands_are_run():
    assert {p.name for p in RUNNABLE} >= {"README.md", "getting-started.md", "cli.md", "calibration.md"}


# Three pages run at a time (their blocks are mostly one process on one core), each in its own
# directory; a block that times a board against its client (a simulated board at up to 2 kHz, a
# recording, a control loop, a benchmark) runs alone, as the rest of the suite does (``realtime``).
# (The demo's 100 Hz board shares: it loses no frame beside two other blocks.)
TIMED = re.compile(r"\bbendsense\s+(?:-\w+\s+)*(?:sim-device|record|live|control)\b|"
                   r"--port\b|benchmarks/|SimulatedDevice|Driver\(")
PAGES_AT_ONCE = 3


class _Turns:
    """Blocks share the machine (PAGES_AT_ONCE at a time); a timed block waits until it is alone, and keeps it."""

    def __init__(self):
        self._cond = threading.Condition()
        self._shared = 0
        self._alone = False

    @contextlib.contextmanager
    def turn(self, alone: bool):
        with self._cond:
            self._cond.wait_for(lambda: not self._alone and (not alone or self._shared == 0))
            if alone:
                self._alone = True
            else:
                self._shared += 1
        try:
            yield
        finally:
            with self._cond:
                if alone:
                    self._alone = False
                else:
                    self._shared -= 1
                self._cond.notify_all()


class _FirstBlocks:
    """The first blocks of the pages, each run once: the first block of a page runs in a directory that holds only
    the copies of the repository (the same for every page), so a page whose first block is another's (``bendsense
    demo``: README.md, getting-started.md) takes that run's output and the files it made."""

    def __init__(self, root: Path):
        self.root, self._lock, self._runs = root, threading.Lock(), {}

    def run(self, lang: str, code: str, work: Path, run) -> subprocess.CompletedProcess:
        with self._lock:
            future = self._runs.get((lang, code))
            mine = future is None
            if mine:
                future = self._runs[(lang, code)] = Future()
        if mine:
            try:
                before = set(os.listdir(work))
                proc = run()
                made = Path(tempfile.mkdtemp(prefix="first-block-", dir=self.root))  # its files, as they were after it
                for name in set(os.listdir(work)) - before:
                    _copy(work / name, made / name)
            except BaseException as err:
                future.set_exception(err)
                raise
            future.set_result((proc, made))
            return proc
        proc, made = future.result()
        for path in made.iterdir():
            _copy(path, work / path.name)
        return proc


def _copy(src: Path, dst: Path):
    """Copy a file or directory a block made; a file a background command removed meanwhile (a lock) is not copied."""
    try:
        if src.is_dir() and not src.is_symlink():
            shutil.copytree(src, dst, symlinks=True)
        else:
            shutil.copy2(src, dst, follow_symlinks=False)
    except FileNotFoundError:
        if src.exists():
            raise


def _run_page(page: Path, work: Path, turns: _Turns, firsts: _FirstBlocks) -> list[str]:
    """Run every block of ``page`` in ``work``; the problems found (empty: the page runs as documented)."""
    blocks = extract_steps(page.read_text(encoding="utf-8"))
    for name in COPIED:
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, work / name, ignore=shutil.ignore_patterns("__pycache__"))
    for name in COPIED_FILES:
        (work / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(ROOT / name, work / name)
    # single-threaded BLAS as the CLI sets it (troubleshooting.md): the python blocks'
    # many small matrices crawl when threaded BLAS competes for the cores
    env = dict(os.environ, MPLBACKEND="Agg", OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    interpreter = _Interpreter(work, env)
    try:
        for k, (lang, code, outputs) in enumerate(blocks, start=1):
            def run(lang=lang, code=code):
                with turns.turn(alone=bool(TIMED.search(code))):
                    return _run_block(lang, code, work, env, interpreter)

            proc = firsts.run(lang, code, work, run) if k == 1 else run()
            if proc.returncode != 0:
                return [f"{page.name}, runnable block {k} ({lang}) exited {proc.returncode}:\n{code}\n"
                        f"--- stdout\n{proc.stdout[-3000:]}\n--- stderr\n{proc.stderr[-3000:]}"]
            for documented in outputs:
                missing = missing_output(documented, proc.stdout + "\n" + proc.stderr)
                if missing:
                    return [f"{page.name}, the documented output of runnable block {k} ({lang}) is not what it "
                            f"prints;\ndocumented lines not printed (masked):\n" + "\n".join(missing) + "\n"
                            f"--- stdout\n{proc.stdout[-3000:]}\n--- stderr\n{proc.stderr[-3000:]}"]
    finally:
        interpreter.close()
    return []


@pytest.fixture(scope="module")
def page_runs(request, tmp_path_factory):
    """The selected pages' runs, started together (PAGES_AT_ONCE at a time) when the first page's test asks."""
    selected = [item.callspec.params["page"] for item in request.session.items
                if getattr(item, "originalname", None) == "test_page_runs"]
    turns, firsts = _Turns(), _FirstBlocks(tmp_path_factory.mktemp("first-blocks"))
    with ThreadPoolExecutor(PAGES_AT_ONCE) as pool:
        yield {page: pool.submit(_run_page, page, tmp_path_factory.mktemp(page.stem), turns, firsts)
               for page in selected}


@pytest.mark.slow
@pytest.mark.parametrize("page", RUNNABLE, ids=[p.relative_to(ROOT).as_posix() for p in RUNNABLE])
def test_page_runs(page: Path, page_runs, request):
    if hasattr(request.config, "workerinput") and request.config.getvalue("loadgroup"):
        # one worker runs every page (tests/conftest.py): without the group in the node id, xdist spreads the pages
        # over the workers and each worker's fixture runs every page
        assert request.node.nodeid.endswith("@docs-pages"), (
            f"{request.node.nodeid}: not grouped; the xdist_group mark of conftest.py did not reach the node id")
    assert shutil.which("bendsense") is not None, "the bendsense command is not on PATH (package not installed)"
    problems = page_runs[page].result()
    assert not problems, problems[0]


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc (Linux)")
def test_run_ends_background_jobs_of_a_failed_block(tmp_path: Path):
    # a block that fails with a background job still running returns at once, job ended
    code = "sleep 60 > /dev/null 2>&1 &\necho $! > job.pid\nfalse\n"
    t0 = time.monotonic()
    proc = _run("bash", code, tmp_path, dict(os.environ))
    assert proc.returncode == 1 and time.monotonic() - t0 < 30
    pid = int((tmp_path / "job.pid").read_text())
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and Path(f"/proc/{pid}").exists():
        time.sleep(0.05)  # the killed job may linger a moment as a zombie of its reaper
        if Path(f"/proc/{pid}/stat").exists() and Path(f"/proc/{pid}/stat").read_text().split()[2] == "Z":
            break
    alive = Path(f"/proc/{pid}/stat").exists() and Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    assert not alive


# ------------------------------------------------------------------ links between pages


def _slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading (and mkdocs' toc: emphasis dropped, a code span's ``_`` kept)."""
    parts = re.split(r"(`[^`]*`)", heading.strip().lower())
    text = "".join(p[1:-1] if p.startswith("`") else re.sub(r"[*_]", "", p) for p in parts)
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", text)
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def _anchors(path: Path) -> set[str]:
    text = FENCE.sub("", path.read_text(encoding="utf-8"))
    return {_slug(m[1]) for m in re.finditer(r"^#{1,6}\s+(.+?)\s*$", text, re.M)}


def test_slug_follows_github():
    assert _slug("Free bending (paper eq. 8–12)") == "free-bending-paper-eq-812"
    assert _slug("1. Install and run the demo") == "1-install-and-run-the-demo"
    assert _slug("ModemManager grabs /dev/ttyACM*") == "modemmanager-grabs-devttyacm"
    assert _slug("A force along the body (`contact_s_m`)") == "a-force-along-the-body-contact_s_m"


@pytest.mark.parametrize("page", PAGES, ids=[p.relative_to(ROOT).as_posix() for p in PAGES])
def test_relative_links_and_anchors_resolve(page: Path):
    text = FENCE.sub("", page.read_text(encoding="utf-8"))
    broken = []
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"[a-z]+:", target):
            continue  # http(s), mailto: not checked offline
        file_part, _, anchor = target.partition("#")
        path = (page.parent / file_part).resolve() if file_part else page
        if not path.exists():
            broken.append(f"{target}: no such file")
        elif anchor and path.suffix == ".md" and anchor not in _anchors(path):
            broken.append(f"{target}: no heading with this anchor")
    assert not broken, f"{page.name}: " + "; ".join(broken)
