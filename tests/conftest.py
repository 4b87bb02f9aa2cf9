"""Fixtures shared by the test modules: a real Dask cluster on localhost."""

from __future__ import annotations

import shutil
import socket
import subprocess
import sys
from pathlib import Path

import pytest


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _dask_command() -> list[str]:
    """The ``dask`` command of this environment (its script beside this Python, else on PATH)."""
    beside = Path(sys.executable).parent / "dask"
    found = str(beside) if beside.exists() else shutil.which("dask")
    assert found, "the dask command is installed with dask[distributed]"
    return [found]


@pytest.fixture
def scheduler():
    """A real ``dask scheduler`` and two ``dask worker`` processes on localhost."""
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    dask = _dask_command()
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    scheduler_args = ["scheduler", "--host", "127.0.0.1", "--port", str(port), "--dashboard-address", ":0"]
    procs = [subprocess.Popen([*dask, *scheduler_args], **quiet)]
    try:
        for _ in range(2):
            worker_args = ["worker", address, "--nthreads", "1", "--no-nanny", "--no-dashboard"]
            procs.append(subprocess.Popen([*dask, *worker_args], **quiet))
        yield address
    finally:
        for p in reversed(procs):  # no nanny: killing a worker leaves no child behind
            p.kill()
        for p in procs:
            p.wait(timeout=30)
