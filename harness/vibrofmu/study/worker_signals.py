"""Preloaded by the workers of a local study cluster (scheduling.connect): they ignore SIGINT.

Ctrl-C in a terminal reaches the whole process group, the workers too; the study's client answers it (it keeps
every finished case, then ends the workers). A worker inheriting SIG_IGN would need the client to ignore SIGINT
while it starts them, and a Ctrl-C then would be lost; until this runs, SIGINT is blocked in the worker (its
spawning thread blocked it: scheduling.spawn_without_sigint).
"""
import signal
import threading

if threading.current_thread() is threading.main_thread():
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def dask_setup(worker):  # (Dask calls it; the import above did the work)
    pass
