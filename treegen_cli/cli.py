"""The `treegen` command line: the root group, its commands (one module each in commands/),
and the entry point, which turns every user error (click's parse errors too) into one line on
stderr and exit 2.
"""

from __future__ import annotations

import signal
import sys
import threading

import click

from . import __version__
from .commands.batch import batch
from .commands.forest import forest
from .commands.info import info
from .commands.make import make
from .commands.preview import preview
from .commands.species import species
from .commands.usage import usage_line
from .errors import Terminated, TreegenError, raise_terminated
from .progress import add_output_options


@click.group(context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(__version__, prog_name="treegen")
def cli():
    """Grow Weber–Penn trees and write them skinned, wind-animated and LOD'd for game engines."""


for command in (info, make, forest, batch, preview, species):
    cli.add_command(command)


def main(argv: list[str] | None = None) -> None:
    """Entry point: run the CLI, turning user errors into one line and exit code 2."""
    add_output_options(cli)  # -q/--quiet, -v/--verbose on every registered command
    if threading.current_thread() is threading.main_thread():  # (tests call main in threads)
        signal.signal(signal.SIGTERM, raise_terminated)  # SIGTERM cleans up as Ctrl-C does
    try:
        cli.main(args=argv, prog_name="treegen", standalone_mode=False)
    except TreegenError as e:
        click.echo(f"treegen: error: {e}", err=True)
        sys.exit(2)
    except click.exceptions.NoArgsIsHelpError as e:  # bare `treegen`: the help, as click prints it
        e.show()
        sys.exit(e.exit_code)
    except click.UsageError as e:  # click's parse errors: one line too, not usage + hint + error
        args = sys.argv[1:] if argv is None else argv
        command = args[0] if args and args[0] in cli.commands else None
        click.echo(f"treegen: error: {usage_line(e, command)}", err=True)
        sys.exit(2)
    except click.exceptions.Abort as e:
        if isinstance(e.__cause__, Terminated):
            click.echo("treegen: terminated", err=True)
            sys.exit(143)
        click.echo("treegen: aborted", err=True)
        sys.exit(130)
    except click.ClickException as e:
        e.show()
        sys.exit(e.exit_code)
    except click.exceptions.Exit as e:
        sys.exit(e.exit_code)
    sys.exit(0)
