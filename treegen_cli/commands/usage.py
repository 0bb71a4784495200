"""click's own parse errors (bad value, unknown option, missing or extra argument) as one line.

click prints a usage line, a help hint, a blank line and `Error: …`; the project's rule is one
line naming the flag as typed and what is allowed, so the entry point words every
click.UsageError here instead, keeping click's content (choices, did-you-mean).
"""

from __future__ import annotations

import re

import click

# click's BadParameter texts read "'abc' is not a valid integer." / "'x' is not one of 'a', 'b'."
_VALUE_IS = re.compile(r"^(?P<value>'[^']*'|\"[^\"]*\") is (?P<rule>.+?)\.?$", re.S)
# click's BadOptionUsage texts read "Option '--seed' requires an argument."
_OPTION = re.compile(r"^Option '[^']*' (?P<rule>.+?)\.?$", re.S)


def usage_line(e: click.UsageError, command: str | None = None) -> str:
    """The one-line message for a click usage error, prefixed with the subcommand (`make: …`);
    `command` names it when click gives no context (an option missing its value)."""
    ctx = e.ctx
    where = f"{command}: " if command and ctx is None else ""
    if ctx is not None and ctx.parent is not None:
        where = ctx.command_path.partition(" ")[2] + ": "
    return where + " ".join(_message(e, ctx).split())


def _message(e: click.UsageError, ctx: click.Context | None) -> str:
    if isinstance(e, click.NoSuchOption):
        return f"unknown option {e.option_name}" + _did_you_mean(e.possibilities)
    if isinstance(e, click.exceptions.NoSuchCommand):
        group = ctx.command if ctx is not None else None
        allowed = ", ".join(group.list_commands(ctx)) if isinstance(group, click.Group) and ctx else ""
        return (
            f"unknown command '{e.command_name}'"
            + _did_you_mean(e.possibilities)
            + (f"; commands: {allowed}" if allowed else "")
        )
    if isinstance(e, click.MissingParameter) and e.param is not None:
        return f"missing {e.param.param_type_name} {_name(e.param)}{_usage(ctx)}"
    if isinstance(e, click.BadParameter) and e.param is not None:
        m = _VALUE_IS.match(e.message)
        if m:
            return f"{_name(e.param)} {m['value']}: {m['rule']}"
        return f"{_name(e.param)}: {e.message.rstrip('.')}"
    if isinstance(e, click.BadOptionUsage):
        m = _OPTION.match(e.message)
        return f"{e.option_name}: {m['rule']}" if m else e.message.rstrip(".")
    extra = re.match(r"^Got unexpected extra arguments? \((?P<args>.*)\)$", e.message)
    if extra:
        args = extra["args"].split()
        what = "argument" if len(args) == 1 else "arguments"
        return f"unexpected extra {what} {' '.join(repr(a) for a in args)}{_usage(ctx)}"
    return e.format_message().rstrip(".")


def _name(param: click.Parameter) -> str:
    """An option as its spellings (`-o/--output`), an argument as its metavar (`SPECIES`)."""
    if isinstance(param, click.Option):
        return "/".join(param.opts)
    return param.human_readable_name


def _did_you_mean(possibilities: list[str] | None) -> str:
    """click's close matches, best first."""
    if not possibilities:
        return ""
    *rest, last = possibilities
    return f" (did you mean {', '.join(rest) + ' or ' if rest else ''}{last}?)"


def _usage(ctx: click.Context | None) -> str:
    """`; usage: treegen make [OPTIONS] SPECIES`, what the command takes."""
    if ctx is None:
        return ""
    return f"; usage: {ctx.command_path} {' '.join(ctx.command.collect_usage_pieces(ctx))}"
