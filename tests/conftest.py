"""Fixtures shared by the tests (plain helpers are in ``helpers.py``)."""

import pytest

from bendsense import load_config


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


@pytest.fixture(scope="session", autouse=True)
def live_step_ready(tmp_path_factory, calibration_path):
    """The compiled live step in numba's cache before the first test: compiled once, by one worker at a time.

    On a fresh install (the README's commands: the demo, then the suite) nothing has
    compiled ``bendsense.pipeline._kernels.live_block`` yet, and every ``record --estimate``,
    ``live`` or ``control`` a test starts would compile it at once (a minute of CPU each):
    the realtime tests' boards would starve meanwhile. The first worker compiles it under a
    lock the others wait on, then load it; with a warm cache this is a cache load (~1 s).
    """
    from bendsense.calibration import Calibration
    from bendsense.pipeline import LiveProcessor

    try:
        import fcntl
    except ImportError:  # not POSIX: each worker on its own
        fcntl = None
    lock = tmp_path_factory.getbasetemp().parent / "live-step.lock"  # shared by the xdist workers of this run
    with open(lock, "w") as fh:
        if fcntl is not None:
            fcntl.flock(fh, fcntl.LOCK_EX)
        LiveProcessor(Calibration.load(calibration_path), load_config()).warm_up()


@pytest.hookimpl(wrapper=True)
def pytest_collection_modifyitems(config, items):
    """Under pytest-xdist (``-n 2 --dist loadgroup``): groups of tests that one worker runs, one after the other.

    A ``realtime`` test times a simulated board against its client; two of them at once
    would each take a core from the other. The documentation pages run from one fixture
    that starts every page selected (tests/docs/test_docs.py): on two workers they would
    run twice. The other worker goes on with the rest.

    xdist's worker turns the ``xdist_group`` marks into the ``@group`` suffix of the node ids
    its scheduler groups by, in its own hook of this name: the marks are added before it (a
    wrapper), and the suffix after it where xdist's did not take (xdist 3.8 writes
    ``item._nodeid``, which pytest 9.2's structured node ids ignore: pytest-xdist#1386).
    The ``page_runs`` fixture of tests/docs/test_docs.py checks that the pages are grouped.
    """
    for item in items:
        if getattr(item, "originalname", None) == "test_page_runs":
            item.add_marker(pytest.mark.xdist_group("docs-pages"))
        elif item.get_closest_marker("realtime") is not None:
            item.add_marker(pytest.mark.xdist_group("realtime"))
    result = yield
    if getattr(config.option, "loadgroup", False):
        for item in items:
            names = sorted({str(m.args[0] if m.args else m.kwargs.get("name", "default"))
                            for m in item.iter_markers("xdist_group")})
            if names and not item.nodeid.endswith("@" + "_".join(names)):
                _set_nodeid(item, f"{item.nodeid}@{'_'.join(names)}")
    return result


def _set_nodeid(item, nodeid):
    if hasattr(item, "_id"):  # pytest >= 9.2: a structured node id, its string cached as given
        from _pytest.nodeid import NodeId

        item._id = NodeId.parse(nodeid)
    else:
        item._nodeid = nodeid
