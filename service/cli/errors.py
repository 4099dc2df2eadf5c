"""Every CLI mistake ends in one line on stderr and a non-zero exit, never a traceback.

``run(app)`` runs the typer app without click's standalone mode and turns what escapes into
one line: usage errors (unknown command, bad option value, missing argument) exit 2, skyfix's
own errors (a missing or corrupt database, bad input) and file-system errors exit 2, anything
else exits 1 with its type named. ``SKYFIX_DEBUG=1`` re-raises, for a traceback.
"""

from __future__ import annotations

import os
import sys
from typing import Any

import click
import typer

try:  # typer >= 0.24 carries its own copy of click
    from typer._click import exceptions as _tcx
except ImportError:  # pragma: no cover - older typer uses click itself
    _tcx = click.exceptions

UsageError = (click.UsageError, _tcx.UsageError)
ClickException = (click.ClickException, _tcx.ClickException)
NoArgsIsHelp = tuple(getattr(m, "NoArgsIsHelpError", ()) for m in (click.exceptions, _tcx)
                     if getattr(m, "NoArgsIsHelpError", None))
ExitLike = (click.exceptions.Exit, typer.Exit)
AbortLike = (click.exceptions.Abort, typer.Abort)

USAGE_EXIT = 2
ERROR_EXIT = 2
BUG_EXIT = 1


def one_line(text: str) -> str:
    """``text`` on one line (newlines folded into '; ')."""
    return "; ".join(part.strip() for part in str(text).splitlines() if part.strip())


def describe(exc: BaseException) -> tuple[str, int]:
    """The one-line message and the exit status of an exception that reached the CLI's top."""
    from ..core.errors import SkyfixError

    if isinstance(exc, UsageError):
        ctx = getattr(exc, "ctx", None)
        where = ctx.command_path if ctx is not None else "skyfix"
        return f"{where}: {one_line(exc.format_message())} (see {where} --help)", USAGE_EXIT
    if isinstance(exc, ClickException):
        return f"skyfix: {one_line(exc.format_message())}", getattr(exc, 'exit_code', 0) or ERROR_EXIT
    if isinstance(exc, SkyfixError):
        return f"skyfix: {one_line(str(exc))}", ERROR_EXIT
    if isinstance(exc, OSError):
        what = exc.strerror or str(exc)
        return (f"skyfix: {exc.filename}: {what}" if exc.filename else f"skyfix: {one_line(what)}"), ERROR_EXIT
    if isinstance(exc, MemoryError):
        return "skyfix: out of memory", ERROR_EXIT
    return f"skyfix: {type(exc).__name__}: {one_line(str(exc))} (SKYFIX_DEBUG=1 shows the traceback)", BUG_EXIT


def run(app: Any, args: list[str] | None = None) -> int:
    """Run ``app`` (a typer app) and return its exit status; errors become one line on stderr."""
    try:
        status = app(args=args, prog_name="skyfix", standalone_mode=False)
    except NoArgsIsHelp as exc:  # `skyfix`, `skyfix db`: the help
        ctx = getattr(exc, "ctx", None)
        if ctx is not None:
            click.echo(ctx.get_help(), err=True)
        return USAGE_EXIT
    except AbortLike:
        click.echo("skyfix: aborted", err=True)
        return 130
    except KeyboardInterrupt:
        click.echo("skyfix: interrupted", err=True)
        return 130
    except ExitLike as exc:
        return int(exc.exit_code or 0)
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except BrokenPipeError:  # `skyfix solve ... | head`
        sys.stderr.close()
        return 0
    except Exception as exc:  # noqa: BLE001 - the point: one line, never a traceback
        if os.environ.get("SKYFIX_DEBUG"):
            raise
        message, status = describe(exc)
        click.echo(message, err=True)
        return status
    return int(status) if isinstance(status, int) else 0
