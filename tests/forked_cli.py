"""A server that runs ``python -m montecarlo ARGS`` in forked children of one preloaded process.

Used by the tests of the command line (:func:`montecarlo_cli`, and ``tests/test_bad_inputs.py``):
most of a short command-line run, as a fresh process, is spent importing the libraries. This
server imports them, and every module of the package, once (:func:`preload`); each request
then forks a child that runs the package's ``__main__`` exactly as ``python -m`` does
(``runpy``, ``sys.argv``, exit code from ``SystemExit``, an uncaught exception printed as a
traceback with exit code 1), in its own working directory and environment with its own stdin,
stdout and stderr: a process of its own, as a test of exit codes, output and files written needs.

Protocol: one JSON object per line on stdin, ``{"argv": [...], "cwd": DIR, "stdout": FILE,
"stderr": FILE, "timeout": SECONDS, "env": {NAME: VALUE} or null}``; one JSON line back per
request, ``{"returncode": INT or null, "timed_out": BOOL}``. End of input ends the server.
"""

from __future__ import annotations

import atexit
import contextlib
import importlib
import json
import os
import pkgutil
import runpy
import signal
import subprocess
import sys
import tempfile
import time
import traceback
from pathlib import Path
from typing import Any

TIMEOUT = 600


def _exit_code(exc: SystemExit) -> int:
    """The process exit code ``python`` gives for an uncaught ``SystemExit``."""
    if exc.code is None:
        return 0
    if isinstance(exc.code, int):
        return exc.code
    print(exc.code, file=sys.stderr)
    return 1


def _child(request: dict) -> None:
    """In the forked child: become ``python -m montecarlo ARGV``; never returns."""
    code = 1
    try:
        if request.get("env") is not None:
            os.environ.clear()
            os.environ.update(request["env"])
        os.chdir(request["cwd"])
        os.dup2(os.open(os.devnull, os.O_RDONLY), 0)
        for fd, key in ((1, "stdout"), (2, "stderr")):
            os.dup2(os.open(request[key], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644), fd)
        sys.argv = ["montecarlo", *request["argv"]]
        try:
            runpy.run_module("montecarlo", run_name="__main__", alter_sys=True)
            code = 0
        except SystemExit as exc:
            code = _exit_code(exc)
        except BaseException:
            traceback.print_exc()
            code = 1
        sys.stdout.flush()
        sys.stderr.flush()
    finally:
        os._exit(code)


def _run(request: dict) -> dict:
    """Fork one child for ``request`` and wait for it, killing it after its timeout."""
    pid = os.fork()
    if pid == 0:
        _child(request)
    deadline = time.monotonic() + request["timeout"]
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return {"returncode": os.waitstatus_to_exitcode(status), "timed_out": False}
        if time.monotonic() > deadline:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            return {"returncode": None, "timed_out": True}
        time.sleep(0.002)


def preload() -> None:
    """Import every module of the package (its commands import theirs on first use: SALib,
    numba, pyarrow, matplotlib...) and pyplot, so that a child only runs its command. The
    package's modules only define things when imported (none reads the environment, starts a
    thread or writes a file), so a child runs as a fresh ``python -m`` would. A module that
    cannot be imported here is left to the child, which fails on it as ``python -m`` would."""
    import matplotlib.pyplot  # noqa: F401

    import montecarlo

    for module in pkgutil.walk_packages(montecarlo.__path__, "montecarlo.",
                                        onerror=lambda name: None):
        if module.name != "montecarlo.__main__":  # the command line itself: the child's part
            with contextlib.suppress(Exception):
                importlib.import_module(module.name)


def serve() -> None:
    """Answer requests on stdin until it closes."""
    preload()

    replies = os.fdopen(os.dup(1), "w")
    os.dup2(os.open(os.devnull, os.O_WRONLY), 1)  # nothing of the server's own reaches replies
    for line in sys.stdin:
        replies.write(json.dumps(_run(json.loads(line))) + "\n")
        replies.flush()


class ForkedCli:
    """One server (this module run as a script): ``python -m montecarlo`` with its imports
    done."""

    def __init__(self) -> None:
        # one BLAS thread: no BLAS thread pool in the server when it forks
        env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONDONTWRITEBYTECODE": "1",
               "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
        self.server = subprocess.Popen([sys.executable, __file__], stdin=subprocess.PIPE,
                                       stdout=subprocess.PIPE, text=True, env=env)

    def run(self, argv: list[str], cwd: Path, out: Path, err: Path, timeout: float = TIMEOUT,
            env: dict[str, str] | None = None) -> dict[str, Any]:
        """Run the command line in ``cwd`` (with the environment ``env``, else the server's),
        its output into the files ``out`` and ``err``; returns its exit code and whether it
        timed out."""
        assert self.server.stdin is not None and self.server.stdout is not None
        request = {"argv": argv, "cwd": str(cwd), "stdout": str(out), "stderr": str(err),
                   "timeout": timeout, "env": env}
        self.server.stdin.write(json.dumps(request) + "\n")
        self.server.stdin.flush()
        reply = self.server.stdout.readline()
        assert reply, f"the command-line server stopped (exit {self.server.poll()})"
        return json.loads(reply)

    def close(self) -> None:
        assert self.server.stdin is not None and self.server.stdout is not None
        self.server.stdin.close()
        self.server.wait(timeout=TIMEOUT)
        self.server.stdout.close()


_SHARED: list[ForkedCli] = []


def montecarlo_cli(*args: Any, cwd: str | Path | None = None, timeout: float = TIMEOUT,
                   env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """``subprocess.run([python, "-m", "montecarlo", *args], capture_output=True, text=True)``
    in a child forked from this test process's server (started on first use), in ``cwd`` with
    ``env`` (else this process's environment now): the same exit code, output and files,
    without importing the libraries again. A run past ``timeout``
    raises ``subprocess.TimeoutExpired`` as ``subprocess.run`` does."""
    if not _SHARED:
        _SHARED.append(ForkedCli())
        atexit.register(_SHARED[0].close)
    argv = [str(a) for a in args]
    with tempfile.TemporaryDirectory(prefix="forked-cli-") as tmp:
        out, err = Path(tmp) / "stdout", Path(tmp) / "stderr"
        reply = _SHARED[0].run(argv, Path(cwd or os.getcwd()).resolve(), out, err, timeout,
                               dict(os.environ) if env is None else env)
        if reply["timed_out"]:
            raise subprocess.TimeoutExpired(["montecarlo", *argv], timeout)
        return subprocess.CompletedProcess(["montecarlo", *argv], reply["returncode"],
                                           out.read_text(), err.read_text())


if __name__ == "__main__":
    serve()
