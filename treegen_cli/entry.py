"""The `treegen` console script. Loading the CLI's modules (numpy, scipy, the pipeline) takes
most of a second: a Ctrl-C then ends as one during a run does, with one line and exit 130, not
a traceback."""

from __future__ import annotations

import sys


def main() -> None:
    try:
        from .cli import main as run
    except KeyboardInterrupt:
        sys.stderr.write("treegen: aborted\n")
        raise SystemExit(130) from None
    run()
