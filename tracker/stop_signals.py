"""The signals that stop a run: Ctrl-C's SIGINT, SIGTERM (what ``timeout``, systemd, Docker and job schedulers send)
and SIGHUP (a closed terminal).

While :func:`like_ctrl_c` is in force (``tracker``'s main), SIGTERM and SIGHUP raise :class:`Stopped`, a
KeyboardInterrupt, in the main thread, as Python raises KeyboardInterrupt on Ctrl-C: every path that keeps the work
done on Ctrl-C keeps it on them too.  A signal the process was started ignoring stays ignored (``nohup`` ignores
SIGHUP so that a closed terminal does not stop the run).  A stopped run exits with 128 plus the signal's number, as
a shell reports a process the signal ended: 130 after Ctrl-C, 143 after SIGTERM, 129 after SIGHUP.

A service manager may signal every process of the run, not only the first.  Worker processes (the keypoint
detector's) leave the stop to their parent, which keeps what they did and then ends them (:func:`end`): they are
started with the signals held back (:func:`held`) and ignore them (:func:`ignore`).
"""

from __future__ import annotations

import atexit
import signal
import threading
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from multiprocessing.process import BaseProcess

STOPS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
"""The signals that stop a run."""

INTERRUPTED = 128 + signal.SIGINT
"""The exit code of a run stopped by Ctrl-C (130)."""


class Stopped(KeyboardInterrupt):
    """Raised in the main thread on SIGTERM or SIGHUP (:func:`like_ctrl_c`) as Python raises KeyboardInterrupt on
    Ctrl-C; ``number`` is the signal's."""

    def __init__(self, number: int):
        super().__init__(signal.Signals(number).name)
        self.number = number


def stopped_within(error: BaseException) -> bool:
    """Whether ``error`` reports a stop: a KeyboardInterrupt raised while native code ran Python (numba's compiled
    functions call some), which that code then reports as a SystemError caused by it."""
    seen: BaseException | None = error
    while seen is not None:
        if isinstance(seen, KeyboardInterrupt):
            return True
        seen = seen.__cause__ or seen.__context__
    return False


def exit_code(number: int) -> int:
    """The exit code of a run the signal ``number`` stopped: 128 plus its number."""
    return 128 + number


@dataclass
class Received:
    """The first SIGTERM or SIGHUP received while :func:`like_ctrl_c` was in force (None: none was)."""

    number: int | None = None

    def exit_code(self, code: int) -> int:
        """The run's exit code ``code``, or, for a run stopped as by Ctrl-C (130) after SIGTERM or SIGHUP,
        :func:`exit_code` of that signal."""
        return exit_code(self.number) if code == INTERRUPTED and self.number is not None else code


@contextmanager
def handling(numbers: Iterable[int], handler: Callable) -> Iterator[None]:
    """``handler`` for the signals ``numbers`` while the block runs, then the handlers before it; a signal ignored
    when the block starts (or handled outside Python) is left as it is, and so is every signal outside the main
    thread, where Python cannot set a handler."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    before = {number: signal.getsignal(number) for number in numbers}
    taken = [number for number, old in before.items() if old not in (signal.SIG_IGN, None)]
    for number in taken:
        signal.signal(number, handler)
    try:
        yield
    finally:
        for number in taken:
            signal.signal(number, before[number])


@contextmanager
def like_ctrl_c() -> Iterator[Received]:
    """SIGTERM and SIGHUP raise :class:`Stopped` while the block runs (module docstring); yields what was received."""
    received = Received()

    def stop(number: int, frame) -> None:
        if received.number is None:
            received.number = number
        raise Stopped(number)

    with handling((signal.SIGTERM, signal.SIGHUP), stop):
        yield received


@contextmanager
def kept() -> Iterator[None]:
    """The stop signals' handlers restored after the block, for a library that sets its own (in the main thread)."""
    before = {number: signal.getsignal(number) for number in STOPS}
    try:
        yield
    finally:
        if threading.current_thread() is threading.main_thread():
            for number, handler in before.items():
                if handler is not None:
                    signal.signal(number, handler)


@contextmanager
def held(numbers: Iterable[int] = STOPS) -> Iterator[None]:
    """The stop signals ``numbers`` held back in this thread while the block runs, then acted on: the processes
    started in it (the detector's worker, with its queues) are born with them blocked.  So is multiprocessing's resource
    tracker, started with the first queue: it ignores SIGINT and SIGTERM but not SIGHUP, and one that SIGHUP ended
    makes the queues' cleanup warn at exit that it died."""
    before = signal.pthread_sigmask(signal.SIG_BLOCK, numbers)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, before)


def ignore() -> None:
    """In a worker process: ignore the stop signals; the parent ends it once it has kept what it did."""
    for number in STOPS:
        signal.signal(number, signal.SIG_IGN)


def start(process: BaseProcess) -> None:
    """Start the worker ``process`` (inside :func:`held`), to be ended by :func:`end`, or at exit if it was not: at exit
    multiprocessing ends the daemon processes left with SIGTERM, which a worker ignores, and would wait for it."""
    process.start()
    atexit.register(process.kill)


def end(process: BaseProcess) -> None:
    """End the worker ``process`` (SIGKILL: it ignores the stop signals) and wait for it."""
    atexit.unregister(process.kill)
    process.kill()
    process.join()
