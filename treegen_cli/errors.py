"""The one exception type for mistakes a user can make.

The CLI catches it, prints its message on one line without a traceback and exits 2.
Anything else escaping is a bug in treegen.
"""


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
