"""A server that runs ``python -m montecarlo ARGS`` in forked children of one preloaded process.

Used by ``tests/test_bad_inputs.py``: each case there is one short command-line run, most of
which, as a fresh process, is spent importing the libraries. This server imports them once;
each request then forks a child that runs the package's ``__main__`` exactly as ``python -m``
does (``runpy``, ``sys.argv``, exit code from ``SystemExit``, an uncaught exception printed as a
traceback with exit code 1), in its own working directory with its own stdin, stdout and stderr.

Protocol: one JSON object per line on stdin, ``{"argv": [...], "cwd": DIR, "stdout": FILE,
"stderr": FILE, "timeout": SECONDS}``; one JSON line back per request, ``{"returncode": INT or
null, "timed_out": BOOL}``. End of input ends the server.
"""

from __future__ import annotations

import json
import os
import runpy
import signal
import sys
import time
import traceback

import pandas  # noqa: F401  (preloaded, like the package: what the children share)
import scipy.stats  # noqa: F401

import montecarlo.cli
import montecarlo.engine.runner  # noqa: F401


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


def serve() -> None:
    """Answer requests on stdin until it closes."""
    replies = os.fdopen(os.dup(1), "w")
    os.dup2(os.open(os.devnull, os.O_WRONLY), 1)  # nothing of the server's own reaches replies
    for line in sys.stdin:
        replies.write(json.dumps(_run(json.loads(line))) + "\n")
        replies.flush()


if __name__ == "__main__":
    serve()
