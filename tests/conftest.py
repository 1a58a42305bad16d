"""Fixtures shared by the tests (plain helpers are in ``helpers.py``), and how tests share the machine.

The suite runs on every core (pytest-xdist, ``-n auto --dist loadfile`` in pyproject.toml:
each test file on one worker, so a file's module fixtures are made once). What runs a
simulated board against a client at its frame rate and asserts that the client kept up runs
alone: a test marked ``realtime``, or the part of a test inside ``with machine.alone():``.
It waits until the tests running on the other workers have finished, and they wait for it:
every test holds a shared lock on a file of the run, a part alone holds it exclusively, and
a turnstile keeps a waiting part alone from being overtaken by the others.
"""

import os
from contextlib import contextmanager

import pytest

from bendsense import load_config

try:
    import fcntl
except ImportError:  # not POSIX: no pseudo-terminals either, the realtime tests are skipped there
    fcntl = None


class Machine:
    """The run's machine lock as one test holds it (module docstring); without workers it does nothing."""

    def __init__(self, base=None):
        self._files = None if base is None else (open(base.with_suffix(".turnstile"), "a"),
                                                 open(base.with_suffix(".lock"), "a"))

    def _take(self, mode) -> None:
        turnstile, lock = self._files
        fcntl.flock(turnstile, fcntl.LOCK_EX)  # whoever waits for the lock holds the turnstile: none overtakes it
        try:
            fcntl.flock(lock, mode)
        finally:
            fcntl.flock(turnstile, fcntl.LOCK_UN)

    @contextmanager
    def alone(self):
        """Run the ``with`` block while no other test runs."""
        if self._files is None:
            yield
            return
        fcntl.flock(self._files[1], fcntl.LOCK_UN)  # let go first: two tests that both want to be alone take turns
        self._take(fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(self._files[1], fcntl.LOCK_SH)

    @contextmanager
    def held(self, exclusive: bool):
        if self._files is None:
            yield self
            return
        self._take(fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH)
        try:
            yield self
        finally:
            fcntl.flock(self._files[1], fcntl.LOCK_UN)
            for f in self._files:
                f.close()


@pytest.fixture(autouse=True)
def machine(request, tmp_path_factory):
    """The machine lock this test holds: shared, alone for a ``realtime`` test (module docstring)."""
    workers = fcntl is not None and "PYTEST_XDIST_WORKER" in os.environ
    # the run's directory, shared by its workers
    base = tmp_path_factory.getbasetemp().parent / "machine" if workers else None
    with Machine(base).held(request.node.get_closest_marker("realtime") is not None) as held:
        yield held


@pytest.fixture(scope="session")
def config():
    """The paper's configuration shipped with bendsense."""
    return load_config()


@pytest.fixture(scope="session")
def calibration_path(tmp_path_factory):
    """The calibration of the virtual sensor of seed 0 (as ``bendsense demo`` makes it), saved as YAML."""
    from bendsense.calibration import Calibration
    from bendsense.sim.scenarios import simulate

    root = tmp_path_factory.mktemp("virtual-calibration")
    simulate("calibration", root / "cal", seed=0, frames_per_strip=20)
    Calibration.fit(root / "cal" / "manifest.yaml").save(root / "cal.yaml")
    return root / "cal.yaml"
