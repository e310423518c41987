"""What the MPI tests share: the command, the launcher, the data, a store of embryo made once, and
the rule that a skipped test fails the run (MPI is optional in the build, but not in CI:
scripts/install-deps.sh --tests installs Open MPI, so a build without it fails here)."""

import os
import pathlib
import shutil
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
DATA = ROOT.parent / "shared" / "data"
ISOTOPE = os.environ.get("ISOTOPE", str(ROOT / "build-ci" / "tools" / "isotope"))

_skipped = []


def pytest_runtest_logreport(report):
    if report.skipped:
        _skipped.append(report.nodeid)


def pytest_sessionfinish(session, exitstatus):
    if _skipped and exitstatus == 0:
        print(f"\n{len(_skipped)} skipped, which fails the run: {', '.join(_skipped)}")
        session.exitstatus = 1


def run(args, **kw):
    return subprocess.run([str(a) for a in args], capture_output=True, text=True, timeout=kw.pop("timeout", 600), **kw)


def mpirun(ranks, args, wrapper=None, timeout=600):
    """`mpirun -n RANKS isotope ARGS`, oversubscribed (this machine has 2 cores), as root if need be."""
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_rmaps_base_oversubscribe="1")
    launcher = ["mpirun", "--oversubscribe", "-n", str(ranks)] + ([str(wrapper)] if wrapper else [])
    return run(launcher + [ISOTOPE] + [str(a) for a in args], env=env, timeout=timeout)


@pytest.fixture(scope="session")
def data():
    assert DATA.is_dir(), f"{DATA}: the shared volumes are missing"
    return DATA


@pytest.fixture(scope="session")
def isotope_command():
    assert os.access(ISOTOPE, os.X_OK), f"{ISOTOPE}: the isotope command is missing (set ISOTOPE)"
    assert shutil.which("mpirun"), "mpirun is missing: scripts/install-deps.sh --tests installs Open MPI"
    # Built without MPI, every rank would run alone: test_extract_... finds no "ranks" in the report.
    return ISOTOPE


@pytest.fixture(scope="session")
def embryo_store(tmp_path_factory, data, isotope_command):
    out = tmp_path_factory.mktemp("store") / "embryo.isotope"
    r = run([isotope_command, "convert", data / "embryo_256x256x256_uint8.raw", out, "--quiet"])
    assert r.returncode == 0, r.stderr
    return out
