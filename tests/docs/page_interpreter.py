"""One Python interpreter that runs a documentation page's Python steps (tests/docs/test_docs.py).

Started once per page, in the page's working directory; reads one JSON request per line
on stdin and answers each with one JSON line ``{"returncode": N}`` on stdout. A request
runs one step, its stdout and stderr (file descriptors 1 and 2, so that what a C
library or a child process writes is caught too) appended to the files it names:

- ``{"python": CODE}``: a ``python`` block, or ``python -c CODE``: as ``python -c`` runs
  it, in a fresh ``__main__`` namespace;
- ``{"cli": ARGS}``: ``bendsense ARGS``, the command line's entry point called here
  (``bendsense.cli.main``, as the console script calls it);
- ``{"script": ARGV}``: ``python SCRIPT ARGS...``, the script run as ``__main__``.

The return code is the step's exit status: 0, the ``SystemExit`` code, or 1 after an
uncaught exception (its traceback on stderr), as a fresh interpreter would exit. Before
each step, what a step may change for the next is put back as a fresh interpreter has
it: the working directory, the environment, ``sys.argv`` and ``sys.path``, the warning
filters, the logging set-up (``bendsense`` configures it once per process), numpy's
print options and matplotlib's figures and settings.

What it saves is an interpreter start, the imports and the load of numba's compiled
kernels per command: a command of the docs takes ~1.5 s of CPU in a process of its own,
~0.5 s here.
"""

import json
import logging
import os
import runpy
import sys
import traceback
import warnings


def _reset(cwd, environ, argv, path, filters):
    os.chdir(cwd)
    if os.environ != environ:
        os.environ.clear()
        os.environ.update(environ)
    sys.argv[:] = argv
    sys.path[:] = path
    warnings.filters[:] = filters
    warnings.showwarning = _showwarning
    root = logging.getLogger()
    for handler in root.handlers[:]:
        root.removeHandler(handler)
    root.setLevel(logging.WARNING)
    np.set_printoptions(**_PRINTOPTIONS)
    if "matplotlib.pyplot" in sys.modules:
        sys.modules["matplotlib.pyplot"].close("all")
        sys.modules["matplotlib"].rc_file_defaults()


import numpy as np  # noqa: E402 (every step imports it; here its print options as a fresh interpreter has them)

_PRINTOPTIONS = np.get_printoptions()
_showwarning = warnings.showwarning


def _step(request):
    if "cli" in request:
        from bendsense.cli import main

        sys.argv[:] = ["bendsense", *request["cli"]]
        main.main(request["cli"], prog_name="bendsense")
    elif "script" in request:
        script = request["script"][0]
        sys.argv[:] = list(request["script"])
        sys.path[0] = os.path.dirname(os.path.abspath(script))
        runpy.run_path(script, run_name="__main__")
    else:
        sys.argv[:] = ["-c"]
        sys.path[0] = ""
        exec(compile(request["python"], "<string>", "exec"), {"__name__": "__main__", "__builtins__": __builtins__})


def _exit_status(code):
    if code is None:
        return 0
    if isinstance(code, int):
        return code
    print(code, file=sys.stderr)
    return 1


def serve():
    requests = os.fdopen(os.dup(0), "r", encoding="utf-8")
    replies = os.fdopen(os.dup(1), "w", encoding="utf-8")
    errors = os.dup(2)  # this file's own errors, between steps: to the test's log of it
    devnull = os.open(os.devnull, os.O_RDWR)
    for fd in (0, 1):  # a step reads nothing, and writes only while it runs (into its files)
        os.dup2(devnull, fd)
    cwd, environ, argv = os.getcwd(), dict(os.environ), ["-c"]
    path = ["", *sys.path[1:]]  # as python -c: the working directory first, not this file's
    filters = warnings.filters[:]
    for line in requests:
        request = json.loads(line)
        _reset(cwd, environ, argv, path, filters)
        with open(request["stdout"], "a", encoding="utf-8") as out, open(request["stderr"], "a",
                                                                          encoding="utf-8") as err:
            os.dup2(out.fileno(), 1)
            os.dup2(err.fileno(), 2)
            try:
                _step(request)
                code = 0
            except SystemExit as exc:
                code = _exit_status(exc.code)
            except BaseException:  # noqa: B036 - a fresh interpreter would print it and exit 1
                traceback.print_exc()
                code = 1
            finally:
                sys.stdout.flush()
                sys.stderr.flush()
                os.dup2(devnull, 1)
                os.dup2(errors, 2)
        replies.write(json.dumps({"returncode": code}) + "\n")
        replies.flush()


if __name__ == "__main__":  # (not when a spawned worker process imports this file as its parent's main module)
    serve()
