"""What every test of the Python face shares: the data folder, the command, and the rule that a
skipped test fails the run (a skip is never counted as a pass; a missing file is a failure)."""

import os
import pathlib

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


@pytest.fixture(scope="session")
def data():
    assert DATA.is_dir(), f"{DATA}: the shared volumes are missing"
    return DATA


@pytest.fixture(scope="session")
def isotope_command():
    assert os.access(ISOTOPE, os.X_OK), f"{ISOTOPE}: the isotope command is missing (set ISOTOPE)"
    return ISOTOPE
