"""Ctrl-C (SIGINT) for the whole `vibrofmu` process: the handler cli.main installs, and the check the hosts make
after a failing FMU call.

A SIGINT normally raises KeyboardInterrupt in whatever Python code runs next. Inside a pythonfmu FMU that code may
be the slave's (FMPy runs it in-process): the slave catches it and fails the call with fmi2Error, and its status
shim raises SIGINT again for the host (fmu_src/slave_support.py, fmu_src/fmi2_status_shim.c); at the very first
instruction of a slave's callback no Python code can catch it, and pythonfmu answers fmi2Fatal. Either way the
host sees a failed FMI call rather than a KeyboardInterrupt, so every host that answers a failed call (records
the case, goes on) first calls check(): it raises KeyboardInterrupt when a SIGINT arrived since install().
Standard library only (imported by cli.main).
"""
from __future__ import annotations

import contextlib
import signal
import threading

_received = 0  # SIGINTs received while installed


def _handler(signum, frame):
    global _received
    _received += 1
    raise KeyboardInterrupt


@contextlib.contextmanager
def install():
    """Count SIGINTs (each still raises KeyboardInterrupt, as Python's default handler does) until the end."""
    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        yield  # (SIGINT ignored, as under nohup or in a background job: left so)
        return
    global _received
    _received = 0
    previous = signal.signal(signal.SIGINT, _handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def received() -> int:
    """How many SIGINTs arrived while installed (in this process)."""
    return _received


def check() -> None:
    """Raise KeyboardInterrupt if a SIGINT arrived (the user pressed Ctrl-C; an FMU call may have failed of it)."""
    if _received:
        raise KeyboardInterrupt
