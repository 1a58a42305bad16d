"""A real, small file system for the tests of a full disk: a fresh tmpfs of a given size.

As root (CI), the tmpfs is mounted with ``mount -t tmpfs -o size=...`` on a directory of
the test and unmounted at the end. Otherwise it is mounted inside a user and mount
namespace (``unshare -rm``), which a long-lived helper process holds; commands then run
inside that namespace, where they see the tmpfs. Either way a test uses only
:meth:`SmallDisk.run` (a command, as a subprocess, that sees the file system),
:meth:`SmallDisk.cli` (``bendsense ARGS``: in this process where the mount is seen here),
:meth:`SmallDisk.fill`, :meth:`SmallDisk.files` and :meth:`SmallDisk.copy_out`.
``SMALLDISK_NAMESPACE=1`` takes the namespace way as root too (to test it).
"""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

# the helper inside the namespace: mount, then run one command per request line
_SERVER = r"""
import json, subprocess, sys
root, options = sys.argv[1], sys.argv[2]
subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", root], check=True)
print("ready", flush=True)
for line in sys.stdin:
    req = json.loads(line)
    try:
        p = subprocess.run(req["argv"], cwd=req["cwd"], env=req["env"], capture_output=True, text=True,
                           timeout=req["timeout"])
        reply = {"returncode": p.returncode, "stdout": p.stdout, "stderr": p.stderr}
    except subprocess.TimeoutExpired as err:
        reply = {"returncode": None, "stdout": str(err.stdout or ""), "stderr": str(err.stderr or "") + "TIMEOUT"}
    print(json.dumps(reply), flush=True)
"""

# what the file system holds (relative path -> bytes as latin-1), run where the tmpfs is seen
_LIST = r"""
import json, os, sys
root = sys.argv[1]
out = {}
for d, dirs, files in os.walk(root):
    for name in dirs + files:
        p = os.path.join(d, name)
        rel = os.path.relpath(p, root)
        if rel == "fill":
            continue
        out[rel] = None if os.path.isdir(p) and not os.path.islink(p) else open(p, "rb").read().decode("latin-1")
print(json.dumps(out))
"""

_FILL = r"""
import os, sys
root, leave = sys.argv[1], int(sys.argv[2])
with open(os.path.join(root, "fill"), "ab", buffering=0) as fh:
    chunk = 1 << 16
    while chunk:
        free = os.statvfs(root).f_bavail * os.statvfs(root).f_frsize
        if free <= leave:
            break
        try:
            fh.write(bytes(min(chunk, free - leave)))
        except OSError:
            chunk //= 2
print(os.statvfs(root).f_bavail * os.statvfs(root).f_frsize)
"""


class SmallDisk:
    """A tmpfs of ``size`` bytes mounted at ``path`` (``read_only``: mounted read-only)."""

    def __init__(self, path: Path, size: int, *, read_only: bool = False):
        self.path = Path(path)
        self.path.mkdir(parents=True, exist_ok=True)
        options = f"size={size}" + (",ro" if read_only else "")
        self._server = None
        if os.geteuid() == 0 and os.environ.get("SMALLDISK_NAMESPACE") != "1":
            subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(self.path)], check=True)
        else:
            self._server = subprocess.Popen(["unshare", "-rm", sys.executable, "-c", _SERVER, str(self.path), options],
                                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
            assert self._server.stdout.readline().strip() == "ready"

    def run(self, argv, *, cwd=None, timeout=300, env=None) -> subprocess.CompletedProcess:
        """Run ``argv`` where the tmpfs is mounted; its exit code and output."""
        env = dict(os.environ if env is None else env)
        cwd = str(cwd or os.getcwd())
        argv = [str(a) for a in argv]
        if self._server is None:
            try:
                return subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
            except subprocess.TimeoutExpired as err:
                return subprocess.CompletedProcess(argv, None, str(err.stdout or ""), str(err.stderr or "") + "TIMEOUT")
        self._server.stdin.write(json.dumps({"argv": argv, "cwd": cwd, "env": env, "timeout": timeout}) + "\n")
        self._server.stdin.flush()
        reply = json.loads(self._server.stdout.readline())
        return subprocess.CompletedProcess(argv, reply["returncode"], reply["stdout"], reply["stderr"])

    def cli(self, args, *, timeout=300) -> subprocess.CompletedProcess:
        """``bendsense ARGS`` where the tmpfs is seen; its exit code and output.

        Where the tmpfs is mounted in this process's namespace (as root), the command line's entry point is called
        here (click's ``CliRunner``: the same ``main`` as the console script, its exit code from its ``SystemExit``);
        an exception that escaped it becomes its traceback on stderr and exit code 1, and what the command logged
        is on stderr, as from a process of its own. Otherwise it runs as a process in the namespace.
        """
        args = [str(a) for a in args]
        if self._server is not None:
            return self.run([sys.executable, "-c", "from bendsense.cli import main; main()", *args], timeout=timeout)
        from helpers import run_cli

        return run_cli(args)

    def fill(self, leave: int = 0) -> int:
        """Fill the file system (a file ``fill``) until ``leave`` bytes are free; the bytes free after."""
        result = self.run([sys.executable, "-c", _FILL, self.path, leave])
        assert result.returncode == 0, result.stderr
        return int(result.stdout)

    def files(self) -> dict:
        """Every entry but ``fill``: relative path -> content (None for a directory)."""
        result = self.run([sys.executable, "-c", _LIST, self.path])
        assert result.returncode == 0, result.stderr
        return json.loads(result.stdout)

    def copy_out(self, rel, dest: Path) -> Path:
        """Copy ``rel`` (a file or directory on the tmpfs) to ``dest``, where the test reads it."""
        result = self.run(["cp", "-a", self.path / rel, dest])
        assert result.returncode == 0, result.stderr
        return Path(dest)

    def close(self) -> None:
        """Unmount (or end the namespace that holds the mount)."""
        if self._server is None:
            subprocess.run(["umount", "-l", str(self.path)], check=False)
        else:
            self._server.stdin.close()
            self._server.wait(30)
            self._server.stdout.close()
        shutil.rmtree(self.path, ignore_errors=True)
