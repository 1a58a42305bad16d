"""Calling the compiled kernels as a user sees it: compilation shown as it goes, no numba warnings.

The kernels are compiled by numba on first use and cached on disk next to their modules
(``cache=True``), so only the first run after an install (or a change of the source)
compiles. Later processes load the cache in well under a second. While a kernel
compiles, one line on stderr says what is compiling and how far it is (the functions of
its call tree done out of all, and the seconds so far), updated in place on a terminal
and every 10 s otherwise. numba's compile-time hints (performance, deprecation) are for
developers and never reach a user; a kernel numba cannot cache (which every process would
compile again) is a RuntimeWarning.

Optimisation level: bendsense's kernels are compiled at LLVM level 1 (``NUMBA_OPT=1``)
unless ``NUMBA_OPT`` is set in the environment. It cuts the first compile by a quarter
and the kernels run as fast as at numba's default level 3 (docs/performance.md); the
setting applies only while bendsense's own kernels compile and is restored after.

The cache: a kernel's cached code is fresh while no module with kernels changed
(:func:`sources_stamp`; numba itself checks only the kernel's own module, and the kernels
it calls from others would stay as they were cached). Several processes may start cold at
once (a process pool's workers, a notebook beside a command); reads and writes of
bendsense's cache entries hold one lock file (in the temporary directory), so that no two
processes write numba's cache at once. An index
that cannot be read (left by another version of bendsense, or torn) is a first run, not a
failure: the kernel compiles, saying so, and writes a new one.

Threads: the batch kernels run their ``prange`` loops on numba's ``workqueue`` layer,
which is safe across ``fork`` (a process pool created after an estimate, e.g. by a
user's ``ProcessPoolExecutor``) where GNU OpenMP is not; it may not be entered by two
threads at once, so the calls are serialised by a lock (concurrent callers would only
oversubscribe the cores). ``NUMBA_THREADING_LAYER`` in the environment takes precedence.
"""

import contextlib
import functools
import os
import re
import sys
import threading
import time
import types
import warnings

import numba
from numba.core import types as nb_types
from numba.core.dispatcher import Dispatcher

if "NUMBA_THREADING_LAYER" not in os.environ:
    numba.config.THREADING_LAYER = "workqueue"

_OPT_LEVEL = 1


class StructType(nb_types.StructRef):
    """A numba StructRef type whose fields take their values' types (not literal ones).

    The base of the structures the kernels hold as one object
    (:class:`bendsense.estimation.problem.ProblemRef`, ...): register a subclass with
    ``numba.experimental.structref.register`` and give it a proxy (``define_proxy``).
    """

    def preprocess_fields(self, fields):
        return tuple((name, nb_types.unliteral(typ)) for name, typ in fields)

_lock = threading.Lock()

_ready = set()  # dispatchers called in this process (numba's .signatures is slow to ask)

#: frames from which a batch runs on numba's threads (:func:`bendsense.shape.pcc.reconstruct`,
#: :func:`bendsense.estimation.estimate_force`): below, waking the thread pool costs more than the frames (~2 µs
#: each in the reconstruction, and on a loaded machine far more: a live block of 5 frames waited ~1 ms for it), and
#: a batch below it (~0.1 s of estimates) compiles no parallel kernel, so the workers of a batch find every kernel
#: its warm-up compiled (``bendsense.batch.warm_up``)
PARALLEL_MIN = 2048


def parallel(frames: int) -> bool:
    """Whether a batch of ``frames`` runs on numba's threads: from :data:`PARALLEL_MIN` on (this thread's count > 1)."""
    return frames >= PARALLEL_MIN and numba.get_num_threads() > 1


@contextlib.contextmanager
def serial(frames: int):
    """Run a batch of ``frames`` on the per-frame kernels, in the calling thread, even from :data:`PARALLEL_MIN` on.

    A live loop that fell seconds behind its board gets a block of thousands of frames:
    the parallel batch kernels are not what its warm-up compiled, and compiling them
    there would stall the loop (seconds from the cache, a minute on the first run).
    numba's thread count is per thread: only the caller's is changed, and put back.
    """
    if frames < PARALLEL_MIN:
        yield
        return
    previous = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(previous)


def call(dispatcher, *args):
    """``dispatcher(*args)``; the first call in a process compiles or loads it quietly."""
    with _lock:
        return _call(dispatcher, args)


def _call(dispatcher, args):
    if dispatcher in _ready:
        return dispatcher(*args)
    _ready.add(dispatcher)
    caught = []
    try:
        with warnings.catch_warnings(record=True) as caught, _progress(dispatcher), _optimisation_level():
            warnings.simplefilter("always")  # every warning of the first call recorded, sorted by _pass_on
            return dispatcher(*args)
    finally:
        _pass_on(caught)


def _pass_on(caught):
    """The warnings of a first call, under the caller's filters: numba's hints dropped, a cache refusal loud.

    numba refuses to cache a kernel whose code holds a runtime address (its "dynamic
    globals": a ctypes pointer, ``numba.get_num_threads()`` compiled in): every process
    then compiles it again, tens of seconds, with nothing else to show. That is a bug of
    bendsense's and is passed on as a RuntimeWarning; the other NumbaWarnings
    (performance, deprecation) are for developers.
    """
    from numba.core.errors import NumbaWarning

    for w in caught:
        text = re.sub(r"\x1b\[[0-9;]*m", "", str(w.message))  # numba's terminal highlighting
        if not issubclass(w.category, NumbaWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        elif text.startswith("Cannot cache"):
            warnings.warn(f"bendsense: {text} ({w.filename}:{w.lineno}): every process compiles it again, "
                          "please report this", RuntimeWarning, stacklevel=4)


#: bendsense's modules with compiled kernels (those that end with :func:`guard_cache`), relative to the package
KERNEL_MODULES = (
    "calibration/_kernels.py", "control/_kernels.py", "estimation/_kernels.py", "estimation/problem.py",
    "estimation/uncertainty.py", "mechanics/_actuator_kernels.py", "mechanics/_beam_kernels.py",
    "pipeline/_kernels.py", "results/_kernels.py", "shape/_kernels.py", "tracking/_kalman_kernels.py",
    "tracking/_stream_kernels.py", "tracking/_window_kernels.py",
)

@functools.cache
def sources_stamp() -> tuple:
    """(path, mtime, size) of every module of :data:`KERNEL_MODULES`: part of each kernel's cache stamp.

    numba keeps a kernel's cached code while the file of its own module is unchanged, but
    that code holds the kernels it calls from other modules, inlined or linked in: an edit
    of one of those (a researcher's, in an editable install) would leave its callers' cached
    code as it was, silently, and their results with it. With the stamp of every kernel
    module in each kernel's, an edit of any of them recompiles them all.
    """
    root = os.path.dirname(os.path.abspath(__file__))
    stamps = []
    for name in KERNEL_MODULES:
        try:
            st = os.stat(os.path.join(root, name))
        except OSError:  # not a plain directory of files (a zip): numba's own stamp only
            stamps.append((name, None))
            continue
        stamps.append((name, st.st_mtime_ns, st.st_size))
    return tuple(stamps)


def guard_cache(namespace: dict) -> None:
    """Make the cache reads and writes of the kernels in ``namespace`` (a module's globals) hold the lock file.

    Call at the end of every module that defines ``@njit(cache=True)`` kernels (and list it
    in :data:`KERNEL_MODULES`): each kernel's cache is also stamped with
    :func:`sources_stamp`, so that it is fresh only while no kernel module changed.
    """
    stamp = sources_stamp()
    for obj in list(namespace.values()):
        if isinstance(obj, Dispatcher) and getattr(obj, "_cache", None) is not None:
            cache = obj._cache
            cache_file = getattr(cache, "_cache_file", None)
            if cache_file is not None and not getattr(cache, "_bendsense_stamped", False):
                cache_file._source_stamp = (cache_file._source_stamp, stamp)
                cache._bendsense_stamped = True
            for name in ("load_overload", "save_overload"):
                method = getattr(cache, name)
                if not getattr(method, "_bendsense_locked", False):
                    setattr(cache, name, _locked(method, cache, miss_on_error=name == "load_overload"))


def _locked(method, cache, miss_on_error):
    def locked(self, *args, **kwargs):
        with _cache_lock():
            if not miss_on_error:
                return method(*args, **kwargs)
            try:
                return method(*args, **kwargs)
            except Exception:  # any unreadable entry is a miss, never a failed call
                _drop_index(cache)
                return None

    locked._bendsense_locked = True
    return types.MethodType(locked, cache)


def _drop_index(cache) -> None:
    """Remove a kernel's cache index that cannot be read, so that its compile writes a new one.

    numba reads an index before it checks that the index is of this source: one written
    by another version of bendsense (an upgrade leaves ``__pycache__`` behind) whose
    kernel had the same name and line can pickle a class this version no longer has, and
    a torn write leaves half a file. Either would fail every call of the kernel, and its
    save after a compile; without the index the kernel compiles as on a first run.
    """
    with contextlib.suppress(OSError, AttributeError):
        os.remove(cache._cache_file._index_path)


_cache_rlock = threading.RLock()
_cache_depth = 0


@contextlib.contextmanager
def _cache_lock():
    """One exclusive ``flock`` per user across processes, re-entrant within a process.

    A single lock file (in the temporary directory) for all of bendsense's cache
    entries, so that nested loads cannot deadlock two processes.
    """
    global _cache_depth
    with _cache_rlock:
        if _cache_depth:
            _cache_depth += 1
            try:
                yield
            finally:
                _cache_depth -= 1
            return
        fd = _open_lock_file()
        _cache_depth = 1
        try:
            if fd is not None:
                import fcntl

                fcntl.flock(fd, fcntl.LOCK_EX)
            yield
        finally:
            _cache_depth = 0
            if fd is not None:
                os.close(fd)  # closing releases the lock


def _open_lock_file():
    """The lock file's descriptor, or None where there is no ``flock`` (Windows) or it cannot be opened."""
    try:
        import fcntl  # noqa: F401
    except ImportError:  # Windows: numba's own atomic renames only
        return None
    import tempfile

    uid = os.getuid() if hasattr(os, "getuid") else 0
    try:
        return os.open(os.path.join(tempfile.gettempdir(), f"bendsense-numba-cache-{uid}.lock"),
                       os.O_RDWR | os.O_CREAT, 0o600)
    except OSError:
        return None


@contextlib.contextmanager
def _optimisation_level():
    """Compile at LLVM optimisation level 1 (numba's default is 3), unless ``NUMBA_OPT`` is set.

    numba's setting is changed in place and put back, not through the environment: a
    change of the environment makes numba re-read all of its settings from it, which
    would undo bendsense's threading layer.
    """
    if "NUMBA_OPT" in os.environ:
        yield
        return
    from numba.core import config, registry

    config.reload_config()  # take in any change of the environment now, not halfway through the compile
    registry.cpu_target.target_context.codegen()  # the machine-code level stays the user's
    previous = config.OPT
    config.OPT = getattr(config, "_OptLevel", int)(_OPT_LEVEL)
    try:
        yield
    finally:
        config.OPT = previous


def _cached(dispatcher) -> bool:
    """Whether ``dispatcher`` has a cache index on disk of this source (a compiled version of it).

    An index of another source (an upgrade or an edit leaves the old one behind) or one
    that cannot be read (:func:`_drop_index`) means a compile: it is shown.
    """
    try:
        load_index = dispatcher._cache._cache_file._load_index
    except AttributeError:  # numba internals moved: assume cached, stay quiet
        return True
    try:
        return bool(load_index())
    except Exception:  # unreadable: compiles after the load drops it
        return False


def call_tree(dispatcher) -> set:
    """The bendsense kernels that ``dispatcher`` calls, directly or through others, itself included.

    Read from the names each function's code uses, looked up in its module's globals
    (and one level into imported modules: ``bk.solve_frame``); an upper bound of what
    numba compiles for it. A kernel inlined into its callers (``inline="always"``) is not
    compiled on its own: its callees count, it does not.
    """
    seen, todo = set(), [dispatcher]
    while todo:
        d = todo.pop()
        if d in seen:
            continue
        seen.add(d)
        code, space = d.py_func.__code__, d.py_func.__globals__
        names = set()
        stack = [code]
        while stack:
            c = stack.pop()
            names.update(c.co_names)
            stack.extend(k for k in c.co_consts if isinstance(k, types.CodeType))
        for name in names:
            obj = space.get(name)
            if isinstance(obj, types.ModuleType):
                todo.extend(a for a in (getattr(obj, n, None) for n in names) if isinstance(a, Dispatcher))
            elif isinstance(obj, Dispatcher):
                todo.append(obj)
    return {d for d in seen if d.targetoptions.get("inline") != "always"}


@contextlib.contextmanager
def _progress(dispatcher):
    """Say on stderr what compiles and how far it is, while ``dispatcher``'s first call compiles its tree."""
    if _cached(dispatcher):
        yield
        return
    from numba.core import event

    tree = call_tree(dispatcher)
    done = set()
    state = {"current": dispatcher.py_func.__name__, "last": 0.0}
    start = time.perf_counter()
    tty = sys.stderr.isatty()
    what = _KERNEL_NAMES.get(dispatcher.py_func.__module__, "compiled kernels")

    def show(final=False):
        elapsed = time.perf_counter() - start
        n = min(len(done), len(tree)) if not final else len(tree)
        text = (f"bendsense: compiling the {what} (first run after install, cached for later runs): "
                f"{n}/{len(tree)} functions, {elapsed:.0f} s" + ("" if final else f" ({state['current']})"))
        if tty:
            sys.stderr.write("\r\033[K" + text + ("\n" if final else ""))
        elif final or elapsed - state["last"] >= 10.0 or state["last"] == 0.0:
            state["last"] = max(elapsed, 1e-9)
            sys.stderr.write(text + "\n")
        sys.stderr.flush()

    class Listener(event.Listener):
        def on_start(self, ev):
            d = ev.data.get("dispatcher")
            if d is not None and d in tree:
                state["current"] = d.py_func.__name__

        def on_end(self, ev):
            d = ev.data.get("dispatcher")
            if d is not None and d in tree:
                done.add(d)

    stop = threading.Event()

    def tick():
        while not stop.wait(1.0):
            show()

    show()
    ticker = threading.Thread(target=tick, name="bendsense-compile-progress", daemon=True)
    ticker.start()
    try:
        with event.install_listener("numba:compile", Listener()):
            yield
    finally:
        stop.set()
        ticker.join()
        show(final=True)


_KERNEL_NAMES = {
    "bendsense.estimation._kernels": "estimation kernels",
    "bendsense.mechanics._beam_kernels": "beam solver",
    "bendsense.mechanics._actuator_kernels": "free-bending interpolant",
    "bendsense.shape._kernels": "shape reconstruction",
    "bendsense.calibration._kernels": "shift error model",
    "bendsense.estimation.problem": "estimation set-up",
    "bendsense.estimation.uncertainty": "uncertainty kernels",
    "bendsense.tracking._kalman_kernels": "tracking kernels",
    "bendsense.tracking._stream_kernels": "live tracking kernels",
    "bendsense.tracking._window_kernels": "window check",
    "bendsense.pipeline._kernels": "live step",
    "bendsense.results._kernels": "status rules",
    "bendsense.control._kernels": "force controller's kernels",
}


class Background:
    """Compile a kernel in a second process while this one works; :meth:`wait` before the first call.

    On a cold cache, ``bendsense demo`` simulates and records (the beam solver's kernels)
    while the estimation kernels compile beside it, on the second core: the first run
    takes the longer of the two instead of their sum. The second process writes the
    cache (the lock file keeps the two processes' writes apart) and this one loads it.
    Nothing starts when the kernel is cached. If the second process fails, this one
    compiles on its first call as it would have without it. Use as a context manager:
    leaving it stops a process still running (an error, Ctrl-C), and a second process
    whose parent dies is stopped by the kernel (Linux) or notices within a second.

    Parameters
    ----------
    dispatcher : numba Dispatcher
        The kernel, to tell whether it is cached and to name it.
    target : str
        ``"module:function"``: a function without arguments that compiles it (by a call).
    """

    def __init__(self, dispatcher, target: str):
        self.dispatcher, self.target = dispatcher, target
        self.process = None
        self._log = None

    def __enter__(self):
        if dispatcher_ready(self.dispatcher):
            return self
        import subprocess
        import tempfile

        module, function = self.target.split(":")
        try:
            self._log = tempfile.TemporaryFile(mode="w+")
        except OSError:  # no temporary directory to write to: this process compiles on its first call
            return self
        code = ("from bendsense.stop_signals import exit_with_parent\n"  # as the pool workers do
                f"exit_with_parent({os.getpid()})\n"
                f"from {module} import {function}\n{function}()\n")
        self.process = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.DEVNULL,
                                        stdout=subprocess.DEVNULL, stderr=self._log)
        what = _KERNEL_NAMES.get(self.dispatcher.py_func.__module__, "compiled kernels")
        sys.stderr.write(f"bendsense: compiling the {what} in a second process meanwhile "
                         "(first run after install, cached for later runs)\n")
        sys.stderr.flush()
        self._start = time.perf_counter()
        return self

    def wait(self) -> None:
        """Wait for the second process, showing its progress; return at once if there is none."""
        if self.process is None:
            return
        tty = sys.stderr.isatty()
        last_shown = -10.0
        while self.process.poll() is None:
            elapsed = time.perf_counter() - self._start
            if tty or elapsed - last_shown >= 10.0:
                last_shown = elapsed
                line = self._last_line().removeprefix("bendsense: ")
                text = f"bendsense: waiting for the second process, {line or 'starting'}"
                sys.stderr.write(("\r\033[K" + text) if tty else text + "\n")
                sys.stderr.flush()
            time.sleep(0.5)
        if tty:
            sys.stderr.write("\r\033[K")
        line = self._last_line()
        if self.process.returncode != 0:
            sys.stderr.write("bendsense: the second process could not compile the kernels; compiling here\n")
        elif line:
            sys.stderr.write(line + "\n")  # its last word: "... 59/59 functions, 35 s"
        sys.stderr.flush()
        self.process = None

    def _last_line(self) -> str:
        self._log.seek(0)
        lines = [line.strip() for line in self._log.read().replace("\r", "\n").splitlines() if line.strip()]
        return lines[-1] if lines else ""

    def __exit__(self, *exc):
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=2.0)
            except Exception:  # noqa: BLE001 (it must not outlive us)
                self.process.kill()
        self.process = None
        if self._log is not None:
            self._log.close()
        return False


def dispatcher_ready(dispatcher) -> bool:
    """Whether ``dispatcher`` needs no compile: called in this process already, or cached on disk."""
    return dispatcher in _ready or _cached(dispatcher)
