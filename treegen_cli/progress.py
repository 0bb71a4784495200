"""How commands talk to the user: a progress display on a terminal, --quiet, --verbose.

Result: on an interactive stderr a long `treegen make` shows one transient line
"⠋ mesh ━━━━━━━╺━━━━ 0:00:03" that disappears when done; piped or redirected, nothing extra is
printed at all (no escape codes, no carriage returns). --quiet leaves only errors (and output
explicitly asked for with --json); --verbose adds one stderr line per stage with its seconds.

    add_output_options(cli)            # every command gains -q/--quiet and -v/--verbose
    rep = current_reporter()           # inside a command
    timings = rep.timings(total=9)     # a pipeline.Timings look-alike that drives the display
    with rep.live():
        build_asset(params, seed, options, timings)

`StageTimings` duck-types pipeline.Timings (`stages` dict + `run(name, fn, ...)`), so stages
report progress without the pipeline knowing about terminals.
"""

from __future__ import annotations

import contextlib
import functools
import io
import os
import sys
import time
from dataclasses import dataclass, field

import click

_META_KEY = "treegen.reporter"


@dataclass
class Reporter:
    """Output policy of one command run; progress shows only on an interactive stderr."""

    quiet: bool = False
    verbose: bool = False
    _live: object | None = field(default=None, repr=False)
    _task: object | None = field(default=None, repr=False)

    @property
    def show_progress(self) -> bool:
        if self.quiet:
            return False
        try:
            return sys.stderr.isatty() and os.environ.get("TERM") != "dumb"
        except (AttributeError, ValueError):
            return False

    def detail(self, message: str) -> None:
        """A --verbose line (stderr), printed above the progress display when one is live."""
        if not self.verbose or self.quiet:
            return
        if self._live is not None:
            self._live.console.print(message, markup=False, highlight=False)
        else:
            click.echo(message, err=True)

    @contextlib.contextmanager
    def live(self):
        """Show the progress display for the block (terminal only); always cleared after."""
        if not self.show_progress:
            yield self
            return
        from rich.console import Console
        from rich.progress import BarColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

        console = Console(file=sys.stderr)
        with Progress(
            SpinnerColumn(),
            TextColumn("{task.description:<10}"),
            BarColumn(),
            TimeElapsedColumn(),
            console=console,
            transient=True,
        ) as prog:
            self._live = prog
            self._task = prog.add_task("working", total=None)
            try:
                yield self
            finally:
                self._live = self._task = None

    def stage_started(self, name: str, total: int | None) -> None:
        if self._live is not None:
            self._live.update(self._task, description=name, total=total)

    def stage_done(self, name: str, seconds: float) -> None:
        if self._live is not None:
            self._live.advance(self._task)

    def stage_totals(self, stages: dict[str, float]) -> None:
        """With -v: seconds per stage, summed over its runs (each LOD runs rig, mesh, wind…)."""
        for name, seconds in stages.items():
            self.detail(f"  {name:<10}{seconds:8.3f} s")

    def timings(self, total: int | None = None) -> "StageTimings":
        return StageTimings(reporter=self, total=total)


@dataclass
class StageTimings:
    """Seconds per stage (like pipeline.Timings), reported to a Reporter as stages run.
    `total`: how many stage runs to expect, for the bar (None: an indeterminate pulse)."""

    reporter: Reporter = field(default_factory=Reporter)
    total: int | None = None
    stages: dict[str, float] = field(default_factory=dict)

    def run(self, name, fn, *args, **kwargs):
        self.reporter.stage_started(name, self.total)
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        seconds = time.perf_counter() - t0
        self.stages[name] = self.stages.get(name, 0.0) + seconds
        self.reporter.stage_done(name, seconds)
        return out


def current_reporter() -> Reporter:
    """The Reporter of the running command (a default one outside click)."""
    ctx = click.get_current_context(silent=True)
    if ctx is None:
        return Reporter()
    return ctx.find_root().meta.get(_META_KEY) or Reporter()


def _wrap(callback):
    @functools.wraps(callback)
    def run(*args, quiet=False, verbose=False, **kwargs):
        if quiet and verbose:
            from .errors import TreegenError

            raise TreegenError("--quiet and --verbose: give at most one")
        rep = Reporter(quiet=quiet, verbose=verbose)
        click.get_current_context().find_root().meta[_META_KEY] = rep
        if quiet and not kwargs.get("as_json"):
            # Commands that do not know about the reporter still go silent on stdout.
            with contextlib.redirect_stdout(io.StringIO()):
                return callback(*args, **kwargs)
        return callback(*args, **kwargs)

    run.__treegen_output__ = True
    return run


NOT_VERBOSE = ("preview", "species")  # commands that print no stages or extra counts


def add_output_options(command: click.Command) -> None:
    """Give `command` (and, for a group, every subcommand) -q/--quiet and -v/--verbose;
    idempotent, so it can run at every start-up after all commands are registered."""
    if isinstance(command, click.Group):
        for sub in command.commands.values():
            add_output_options(sub)
        return
    if command.callback is None or getattr(command.callback, "__treegen_output__", False):
        return
    names = {p.name for p in command.params}
    if "quiet" in names or "verbose" in names:
        return
    taken = {o for p in command.params for o in p.opts + p.secondary_opts}
    command.params.append(
        click.Option(
            [o for o in ("-q", "--quiet") if o not in taken],
            is_flag=True,
            help="Print nothing but errors (and --json output).",
        )
    )
    if command.name in NOT_VERBOSE:  # nothing more to say: no -v that would do nothing
        command.callback = _wrap(command.callback)
        return
    command.params.append(
        click.Option(
            [o for o in ("-v", "--verbose") if o not in taken],
            is_flag=True,
            help="Also print each stage's seconds and extra counts (on stderr).",
        )
    )
    command.callback = _wrap(command.callback)
