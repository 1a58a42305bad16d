"""The first run after an install: compilation shown as it goes, at one optimisation level, one cache writer.

And what keeps a first call fast beside other work: bendsense's own linear algebra on
one BLAS thread, and only the kernels a command needs compiled (a live block, a
worker of a process pool and a batch below ``_jit.PARALLEL_MIN`` frames never compile the
batch kernel).
"""

import os
import subprocess
import sys
import textwrap

import numba
import numpy as np
import pytest
import scipy.linalg  # noqa: F401 (loads scipy's BLAS before the limits are read)
from threadpoolctl import threadpool_info, threadpool_limits

import bendsense
from bendsense import _blas, _jit
from bendsense import estimation as est

KERNEL = textwrap.dedent('''
    import numpy as np
    from numba import njit

    from bendsense import _jit


    @njit(cache=True)
    def inner(x):
        return x * 2.0


    @njit(cache=True, inline="always")
    def inlined(x):
        return inner(x)


    @njit(cache=True)
    def outer(a):
        s = 0.0
        for v in a:
            s += inlined(v)
        return s


    _jit.guard_cache(globals())
''')


def _run(tmp_path, code, env_extra=None, **kwargs):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "PYTHONPATH": str(tmp_path)}
    env.pop("NUMBA_OPT", None)
    env.update(env_extra or {})
    return subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, **kwargs)


def test_a_cold_compile_says_what_compiles_and_how_far_then_the_cache_is_quiet(tmp_path):
    (tmp_path / "bs_toy_kernels.py").write_text(KERNEL)
    code = textwrap.dedent('''
        import os, numpy as np, numba
        from bendsense import _jit
        import bs_toy_kernels as k
        print(_jit.call(k.outer, np.arange(4.0)))
        print(sorted(d.py_func.__name__ for d in _jit.call_tree(k.outer)))
        print(os.environ.get("NUMBA_OPT"), int(numba.config.OPT), numba.config.THREADING_LAYER)
    ''')
    first = _run(tmp_path, code)
    out, err = first.communicate(timeout=300)
    assert first.returncode == 0, err
    # the inlined kernel is no compile of its own: two functions, not three
    assert out.split("\n")[:3] == ["12.0", "['inner', 'outer']", "None 3 workqueue"]  # the user's settings are back
    lines = [line for line in err.splitlines() if line.strip()]
    assert lines and lines[-1].startswith("bendsense: compiling the compiled kernels")
    assert lines[-1].endswith("2/2 functions, " + lines[-1].split(", ")[-1]) and " s" in lines[-1]
    again = _run(tmp_path, code)
    out2, err2 = again.communicate(timeout=300)
    assert again.returncode == 0 and out2 == out
    assert err2 == ""  # loaded from the cache: nothing to say


def test_two_cold_processes_compile_side_by_side_and_both_find_the_result(tmp_path):
    """No two processes write the cache at once (a lock file); both compile, both answer, a third loads."""
    (tmp_path / "bs_toy_kernels.py").write_text(KERNEL)
    code = ("import numpy as np\nfrom bendsense import _jit\nimport bs_toy_kernels as k\n"
            "print(_jit.call(k.outer, np.ones(3)))\n")
    procs = [_run(tmp_path, code) for _ in range(2)]
    results = [p.communicate(timeout=300) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], results
    assert [r[0] for r in results] == ["6.0\n", "6.0\n"]
    third = _run(tmp_path, code)
    out, err = third.communicate(timeout=300)
    assert (third.returncode, out, err) == (0, "6.0\n", "")


@pytest.mark.parametrize("stale", ["a class gone", "torn", "another source"])
def test_a_cache_index_this_version_cannot_read_is_a_first_run_not_a_failure(tmp_path, stale):
    """An index left by another version (it pickles a class no longer there, or is of another source) or torn
    mid-write: the kernels compile, saying so, and write an index the next run loads."""
    import pickle

    (tmp_path / "bs_toy_kernels.py").write_text(KERNEL)
    code = ("import numpy as np\nfrom bendsense import _jit\nimport bs_toy_kernels as k\n"
            "print(_jit.call(k.outer, np.ones(3)))\n")
    first = _run(tmp_path, code)
    assert first.communicate(timeout=300)[0] == "6.0\n"
    indexes = sorted((tmp_path / "cache").rglob("*.nbi"))
    assert len(indexes) == 2  # outer's and inner's
    if stale == "another source":  # an upgrade or an edit: numba's index is of the old source's stamp
        (tmp_path / "bs_toy_kernels.py").write_text(KERNEL + "\n# another version\n")
        indexes = []
    for index in indexes:
        with open(index, "rb") as fh:
            version = pickle.load(fh)  # numba's own version header: the body is read only when it matches
            body = fh.read()
        rest = b"cbs_toy_kernels\nGone\n." if stale == "a class gone" else body[:len(body) // 2]
        index.write_bytes(pickle.dumps(version, protocol=-1) + rest)
    again = _run(tmp_path, code)
    out, err = again.communicate(timeout=300)
    assert (again.returncode, out) == (0, "6.0\n"), err
    assert "compiling" in err and "Traceback" not in err
    third = _run(tmp_path, code)  # the compile wrote readable indexes: loaded, quiet
    assert third.communicate(timeout=300) == ("6.0\n", "")


def test_an_edit_of_a_kernel_a_cached_kernel_calls_from_another_module_recompiles_it(tmp_path):
    """numba keeps a kernel's cache while its own file is unchanged, though its code holds the callees' from other
    files: an edit of one of those (an editable install) must not leave the caller's old code running."""
    import shutil

    package = tmp_path / "bendsense"
    shutil.copytree(os.path.dirname(bendsense.__file__), package,
                    ignore=shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc"))
    # shape's frame_curvatures calls calibration's horner (the polynomial), its code linked into the caller's
    code = ("import numpy as np\nfrom bendsense import _jit\nfrom bendsense.shape import _kernels as k\n"
            "kappa, theta = np.zeros(1), np.zeros(1)\n"
            "_jit.call(k.frame_curvatures, np.ones(1), np.zeros(1), np.array([[0.0, 1.0]]), -np.ones(1) * 9,\n"
            "          np.ones(1) * 9, np.ones(1), 1.0, kappa, theta)\n"
            f"print(kappa.tolist(), k.__file__.startswith({str(package)!r}))\n")
    first = _run(tmp_path, code)
    out, err = first.communicate(timeout=300)
    assert (first.returncode, out) == (0, "[1.0] True\n"), err
    callee = package / "calibration" / "_kernels.py"
    text = callee.read_text()
    assert text.count("        acc = acc * x + c[j]\n") == 1
    callee.write_text(text.replace("        acc = acc * x + c[j]\n", "        acc = acc * x + 2.0 * c[j]\n"))
    again = _run(tmp_path, code)
    out, err = again.communicate(timeout=300)
    assert (again.returncode, out) == (0, "[2.0] True\n"), err  # the caller compiled anew
    assert "compiling" in err


def test_the_kernel_modules_stamped_are_every_module_with_kernels():
    """Each module that ends with ``guard_cache(globals())`` is in ``KERNEL_MODULES`` (an edit of it recompiles)."""
    from pathlib import Path

    root = Path(bendsense.__file__).parent
    found = sorted(p.relative_to(root).as_posix() for p in root.rglob("*.py")
                   if "_jit.guard_cache(globals())" in p.read_text(encoding="utf-8"))
    assert found == sorted(_jit.KERNEL_MODULES)
    assert [s[0] for s in _jit.sources_stamp()] == list(_jit.KERNEL_MODULES)
    assert all(len(s) == 3 for s in _jit.sources_stamp())  # each found on disk


def test_the_optimisation_level_of_the_user_is_kept(tmp_path):
    """``NUMBA_OPT`` set by the user is left alone (and not removed after the compile)."""
    (tmp_path / "bs_toy_kernels.py").write_text(KERNEL)
    code = ("import os, numpy as np, numba\nfrom bendsense import _jit\nimport bs_toy_kernels as k\n"
            "_jit.call(k.outer, np.ones(3))\nprint(os.environ['NUMBA_OPT'], int(numba.config.OPT))\n")
    p = _run(tmp_path, code, {"NUMBA_OPT": "2"})
    out, err = p.communicate(timeout=300)
    assert p.returncode == 0, err
    assert out.split() == ["2", "2"]


def test_bendsense_linear_algebra_runs_on_one_blas_thread_and_restores_the_users_setting():
    seen = []

    @_blas.one_thread
    def work():
        seen.append({lib["filepath"]: lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"})
        inner()

    @_blas.one_thread
    def inner():  # nested: still limited, and the outer call restores
        seen.append({lib["filepath"]: lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"})

    with threadpool_limits(limits=2, user_api="blas"):
        before = {lib["filepath"]: lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"}
        work()
        after = {lib["filepath"]: lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"}
    assert before and set(before.values()) == {2}
    assert len(seen) == 2 and all(set(s.values()) == {1} for s in seen)
    assert after == before


def test_a_calibration_fit_limits_blas_while_it_runs(monkeypatch, tmp_path):
    """The calibration's least squares run inside the limit (numpy's lstsq sees one thread)."""
    from bendsense.calibration import polynomials

    threads = []
    real = np.linalg.lstsq

    def spy(*args, **kwargs):
        threads.append({lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"})
        return real(*args, **kwargs)

    monkeypatch.setattr(polynomials.np.linalg, "lstsq", spy)
    from bendsense.sim.scenarios import simulate

    simulate("calibration", tmp_path / "cal", seed=1, frames_per_strip=20)
    with threadpool_limits(limits=2, user_api="blas"):
        bendsense.Calibration.fit(tmp_path / "cal" / "manifest.yaml")
    assert threads and all(t == {1} for t in threads)


def test_small_batches_and_single_threads_use_the_per_frame_kernel_with_the_batch_kernels_results():
    """A batch below ``_jit.PARALLEL_MIN`` (or on one numba thread) runs block by block on the per-frame kernel.

    The same frames through the batch kernel on two threads give the same forces,
    statuses and σ bit for bit: blocks of consecutive frames are chained the same way.
    """
    config = bendsense.load_config()
    rng = np.random.default_rng(3)
    B = _jit.PARALLEL_MIN + 37
    kappa = rng.uniform(2.0, 10.0, (B, 16))
    pressure = rng.uniform(20e3, 90e3, B)
    previous = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = est.estimate_force(kappa, pressure, config, noise_std=0.02)
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        many = est.estimate_force(kappa, pressure, config, noise_std=0.02)
    finally:
        numba.set_num_threads(previous)
    np.testing.assert_array_equal(one.force_n, many.force_n)
    np.testing.assert_array_equal(one.std_n, many.std_n)
    np.testing.assert_array_equal(one.message, many.message)


def test_every_kernel_compiled_here_can_be_cached(monkeypatch):
    """No compiled kernel holds a runtime address (numba's "dynamic globals"), which numba does not cache.

    ``numba.get_num_threads()`` compiled into the batch kernel did (the threading layer's
    function): the kernel then compiled again in every process, ~30 s at the first large
    batch of each ``bendsense batch`` or notebook, and numba's warning of it is silenced
    with its others during a first call (``_jit.call``). The batch kernel is run here on
    a small batch (``_jit.parallel`` forced), then every kernel this process holds is checked.
    """
    from numba.core.caching import NullCache
    from numba.core.registry import CPUDispatcher

    monkeypatch.setattr(_jit, "parallel", lambda frames: True)
    rng = np.random.default_rng(5)
    result = est.estimate_force(rng.uniform(2.0, 10.0, (9, 16)), rng.uniform(20e3, 90e3, 9),
                                bendsense.load_config(), noise_std=0.02)
    assert result.success.all() and est._kernels.estimate_frames.signatures
    kernels = [(f"{module}.{name}", obj) for module, m in list(sys.modules.items()) if module.startswith("bendsense")
               for name, obj in list(vars(m).items()) if isinstance(obj, CPUDispatcher)]
    held = [(name, cres) for name, obj in kernels if not isinstance(obj._cache, NullCache)
            for cres in obj.overloads.values()]
    assert len(held) > 10 and [name for name, cres in held if cres.library.has_dynamic_globals] == []


def test_a_first_call_warns_of_a_kernel_numba_cannot_cache_and_drops_numbas_hints(tmp_path, monkeypatch):
    """A kernel with a runtime address compiled in: a RuntimeWarning; numba's performance hint: nothing."""
    (tmp_path / "toy_kernels.py").write_text(textwrap.dedent('''
        import numba

        @numba.njit(cache=True)
        def threads():
            return numba.get_num_threads()

        @numba.njit(cache=True, parallel=True)
        def plus_one(x):
            return x + 1.0
    '''))
    monkeypatch.syspath_prepend(str(tmp_path))
    import toy_kernels

    with pytest.warns(RuntimeWarning, match=r'Cannot cache compiled function "threads".*compiles it again'):
        assert _jit.call(toy_kernels.threads) == numba.get_num_threads()
    assert _jit.call(toy_kernels.plus_one, 1.0) == 2.0  # its NumbaPerformanceWarning would fail the test


@pytest.mark.parametrize("n", [1, 5])
def test_live_sized_blocks_never_compile_the_batch_kernel(n, calibration_path):
    code = textwrap.dedent(f'''
        import numpy as np, bendsense
        from bendsense.calibration import Calibration
        from bendsense.estimation import _kernels as kernels
        cal = Calibration.load({str(calibration_path)!r})
        bendsense.estimate_force(np.full(({n}, 16), 5.0), np.full({n}, 4e4), bendsense.load_config(), calibration=cal)
        print(len(kernels.estimate_block.signatures), len(kernels.estimate_frames.signatures))
    ''')
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, check=True)
    assert out.stdout.split() == ["1", "0"]


BACKGROUND = textwrap.dedent('''
    import sys, time
    import numpy as np
    from bendsense import _jit
    import bs_toy_kernels as k
    with _jit.Background(k.outer, "bs_toy_kernels:compile_toy") as bg:
        started = bg.process is not None
        if sys.argv[1] == "leave":
            pid = bg.process.pid
    if sys.argv[1] == "leave":  # left before waiting: the second process is gone
        import os
        time.sleep(0.2)
        try:
            os.kill(pid, 0)
            print("alive")
        except ProcessLookupError:
            print("gone")
    else:
        with _jit.Background(k.outer, "bs_toy_kernels:compile_toy") as bg:
            bg.wait()
        print(started, _jit._cached(k.outer), _jit.call(k.outer, np.ones(2)))
''')


@pytest.mark.parametrize("how", ["wait", "leave"])
def test_a_second_process_compiles_meanwhile_and_this_one_loads_its_cache(tmp_path, how):
    (tmp_path / "bs_toy_kernels.py").write_text(KERNEL + "\n\ndef compile_toy():\n    _jit.call(outer, np.ones(1))\n")
    p = _run(tmp_path, BACKGROUND.replace("sys.argv[1]", repr(how)))
    out, err = p.communicate(timeout=300)
    assert p.returncode == 0, err
    if how == "leave":
        assert out.split() == ["gone"]
    else:
        assert out.split() == ["True", "True", "4.0"]
        assert "compiling the compiled kernels in a second process meanwhile" in err
        assert err.rstrip().splitlines()[-1].startswith("bendsense: compiling the compiled kernels")
        assert "2/2 functions" in err.rstrip().splitlines()[-1]  # the second process's last word
