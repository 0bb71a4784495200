"""The one exception type for mistakes a user can make.

The CLI catches it, prints its message on one line without a traceback and exits 2.
Anything else escaping is a bug in treegen.
"""


class TreegenError(Exception):
    """A user-caused error: bad species file, bad option, oversized tree, bad layout.

    The message names the file, the line or JSON path, the key and the allowed range.
    """

    exit_code = 2


def in_file(path, fn, *args):
    """Run `fn(*args)`; a user error it raises is reported against `path` (once)."""
    try:
        return fn(*args)
    except TreegenError as e:
        if str(e).startswith(str(path)):
            raise
        raise TreegenError(f"{path}: {e}") from None
