"""Shared fixtures: every test that needs Taichi runs on the arch given by --arch (cpu by
default), initialised once per session through lss_kernels.kernels.backend."""
import os
from pathlib import Path

import pytest
from hypothesis import settings

# Hypothesis draws the same examples on every run (derandomize) and no example fails for
# taking long on a busy machine: a property test cannot turn a run red at random.
# HYPOTHESIS_PROFILE=explore draws fresh examples, to look for new failures.
settings.register_profile("ci", derandomize=True, deadline=None)
settings.register_profile("explore", deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


def pytest_addoption(parser):
    parser.addoption("--arch", default="cpu", help="Taichi arch for kernel tests")
    parser.addoption("--runslow", action="store_true", help="run tests marked slow")
    parser.addoption("--paper15", default=os.environ.get("LSS_PAPER15"), metavar="DIR",
                     help="folder of the paper's 15 scenes (default: $LSS_PAPER15); the tests "
                          "that read them skip without it")


def pytest_collection_modifyitems(config, items):
    if config.getoption("--runslow"):
        return
    skip = pytest.mark.skip(reason="slow: pass --runslow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(scope="session")
def ti_arch(request):
    from lss_kernels.kernels import backend
    return backend.init(arch=request.config.getoption("--arch"))


@pytest.fixture(scope="session")
def paper15(request):
    """The folder of the paper's 15 scenes (``--paper15`` or ``$LSS_PAPER15``), or a skip."""
    folder = request.config.getoption("--paper15")
    if not folder or not Path(folder).is_dir():
        pytest.skip("the paper's scenes: set LSS_PAPER15 or pass --paper15 DIR")
    return Path(folder)


@pytest.fixture
def fresh_taichi(ti_arch):
    """Taichi started again before a test that builds a solver while a module fixture still
    holds fields that no later test of the module uses (they do not survive it).  A new
    solver does this itself when none of the library's fields is alive
    (:func:`lss_kernels.kernels.backend.fresh_numbering`), and then loads the kernels that
    an earlier solver of its size bucket and parameters compiled instead of compiling them
    again; a live fixture's solver would stop it."""
    from lss_kernels.kernels import backend
    backend.restart()
    return ti_arch


@pytest.fixture(scope="module")
def region(ti_arch):
    """An :class:`~lss_kernels.model.init.InitialRegion` of 24 x 40 pixels, one per module."""
    from lss_kernels.kernels.backend import FieldPool
    from lss_kernels.model.init import InitialRegion
    pool = FieldPool()
    r = InitialRegion(pool, 24, 40)
    pool.finalize()
    return r
