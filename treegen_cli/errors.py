"""The one exception type for mistakes a user can make.

The CLI catches it, prints its message on one line without a traceback and exits 2.
Anything else escaping is a bug in treegen. Also how a stop (Ctrl-C, SIGTERM) reaches the
run: raised where the run is, or held while something must not be cut in two.
"""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from typing import Iterator


class TreegenError(Exception):
    """A user-caused error: bad species file, bad option, oversized tree, bad layout.

    The message names the file, the line or JSON path, the key and the allowed range. `line`:
    the species file's line the message is about, when it was raised without the file's name
    (e.g. by the generator, from Params.line_of); `in_file` puts it after the name.
    """

    exit_code = 2

    def __init__(self, *args, line: int | None = None):
        super().__init__(*args)
        self.line = line


def in_file(path, fn, *args):
    """Run `fn(*args)`; a user error it raises is reported against `path` (once), at its line."""
    try:
        return fn(*args)
    except TreegenError as e:
        if str(e).startswith(str(path)):
            raise
        at = f"{path}:{e.line}" if e.line is not None else f"{path}"
        raise TreegenError(f"{at}: {e}") from None


class OptionError(TreegenError):
    """A stage option out of its range. `field` is the options dataclass's field (`speed`),
    `label` how the message names it when nobody re-words it; the front door (api.resolve)
    re-words it with what the user typed (`--wind-speed`, `entries[0].wind_speed`), keeping
    the value and the allowed range."""

    def __init__(self, field: str, value, rule: str, label: str | None = None):
        self.field, self.value, self.rule, self.label = field, value, rule, label
        super().__init__(self.worded(label or field))

    def __reduce__(self):
        """Pickled whole (its own arguments, not the message alone), so it crosses from a
        worker process to the client as it was raised."""
        return type(self), (self.field, self.value, self.rule, self.label), self.__dict__

    def worded(self, label: str) -> str:
        value = f"{self.value:g}" if isinstance(self.value, float) else str(self.value)
        return f"{label} {value}: {self.rule}"


class Terminated(KeyboardInterrupt):
    """A SIGTERM (a farm or CI stopping the job), raised where the run is, as a Ctrl-C is, so
    the same cleanups run: staging folders removed, a batch's manifest written, the cluster
    closed. The CLI then exits 143 (128 + SIGTERM) where a Ctrl-C exits 130."""


def raise_terminated(signum, frame) -> None:
    raise Terminated()


@contextmanager
def signals_held() -> Iterator[None]:
    """SIGINT and SIGTERM that arrive inside are acted on once it is left, by the handlers
    they were meant for (a Ctrl-C Python ignores stays ignored): what they would cut in two
    finishes first (one asset's file moves; a Dask cluster's start and the close that undoes
    it). The holding handler, once released, passes a signal straight to the handler it
    replaced, so one arriving while the handlers are put back (or set up) reaches its own and
    leaves no signal caught for good; blocking the signals could not ensure that, since
    another thread (Dask's) takes them. Only the main thread can hold them (Python runs
    handlers there); SIGKILL cannot be."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    replaced: dict = {}
    released = False

    def hold(signum, frame):
        if not released:
            caught.append(signum)
        else:
            _deliver(signum, replaced[signum], frame)

    try:
        for sig in (signal.SIGINT, signal.SIGTERM):
            if signal.getsignal(sig) is not None:  # (None: a handler Python did not install)
                replaced[sig] = signal.signal(sig, hold)
        yield
    finally:
        released = True
        stop = _put_back(replaced)
        # to the handlers they were meant for, now; SIGTERM first (SIGINT's raises at once)
        for signum in sorted(set(caught), key=lambda n: n != signal.SIGTERM):
            _deliver(signum, replaced[signum], None)
        if stop is not None:
            raise stop


def _put_back(handlers: dict) -> BaseException | None:
    """Every handler of `handlers` ({signal: handler}) put back, even where one's arrival
    raises midway (it is returned, to be raised once all are back)."""
    left, stop = dict(handlers), None
    while left:
        sig, handler = next(iter(left.items()))
        try:
            signal.signal(sig, handler)
            del left[sig]
        except BaseException as e:  # a stop raised by its (released) handler: the rest go back too
            stop = stop or e
    return stop


def _deliver(signum: int, handler, frame) -> None:
    """What `handler` (a signal.signal disposition) does with `signum`."""
    if callable(handler):
        handler(signum, frame)
    elif handler == signal.SIG_DFL:
        signal.signal(signum, signal.SIG_DFL)
        signal.raise_signal(signum)
