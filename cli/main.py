"""Entry point of the ``cutkit`` console command.

The group is built from :data:`cutkit.cli.commands.COMMANDS`.  User errors
(:class:`cutkit.errors.CutkitError`) become one line on stderr and exit
code 2; Ctrl-C exits with 130.  SIGTERM takes Ctrl-C's path (a run stopped
by it leaves a valid recording and summary) and exits with 143.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import signal
import sys
import threading

import click

from cutkit import __version__
from cutkit.cli.commands import COMMANDS
from cutkit.errors import CutkitError
from cutkit.interrupts import Terminated, request_stop


#: How long after a SIGTERM dropped in a finalizer it is sent again, s.
RESEND_DELAY_S = 0.01


def _on_sigterm(signum, frame):
    # a run loop stops at its next safe point (cutkit.interrupts); anything else stops here
    if not request_stop(Terminated):
        raise Terminated()


def _on_sigint(signum, frame):
    if not request_stop(KeyboardInterrupt):
        raise KeyboardInterrupt()


def _deliver_again(unraisable, previous_hook):
    """``sys.unraisablehook`` while SIGTERM is handled: a :class:`Terminated` raised while Python
    ran a finalizer (``__del__``, a weakref callback) is printed and dropped there, so the run
    would go on; send the signal again instead, from another thread a moment later (sent at
    once, the handler would run still inside the hook), to be raised where the main thread is
    then; if that is a finalizer again, this hook sends it once more."""
    if isinstance(unraisable.exc_value, Terminated):
        resend = threading.Timer(RESEND_DELAY_S, os.kill, args=(os.getpid(), signal.SIGTERM))
        resend.daemon = True
        resend.start()
        return
    previous_hook(unraisable)


class _TableGroup(click.Group):
    """A click group whose commands are the entries of ``COMMANDS``, imported lazily."""

    def list_commands(self, ctx):
        return [name for name, (module, _) in COMMANDS.items() if _module_exists(module)]

    def get_command(self, ctx, name):
        entry = COMMANDS.get(name)
        if entry is None or not _module_exists(entry[0]):
            return None
        module = importlib.import_module(entry[0])
        return _with_threads_option(module.command)

    def format_commands(self, ctx, formatter):
        # Help text comes from the table so that --help imports no command module.
        rows = [(name, COMMANDS[name][1]) for name in self.list_commands(ctx)]
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)

    def invoke(self, ctx):
        previous = None
        previous_hook = sys.unraisablehook
        if threading.current_thread() is threading.main_thread():
            previous = signal.signal(signal.SIGTERM, _on_sigterm), signal.signal(signal.SIGINT, _on_sigint)
            sys.unraisablehook = lambda unraisable: _deliver_again(unraisable, previous_hook)
        try:
            return super().invoke(ctx)
        except CutkitError as err:
            message = " ".join(str(err).split())  # exactly one line
            click.echo(f"cutkit: error: {message}", err=True)
            ctx.exit(err.exit_code)
        except OSError as err:
            # the system refused a read or write (a full disk, a folder taken away): one line, the file named
            where = f"{err.filename}: " if err.filename else ""
            message = " ".join(f"{where}{err.strerror or err}".split())
            click.echo(f"cutkit: error: {message}", err=True)
            ctx.exit(1)
        except Terminated:
            click.echo("cutkit: terminated", err=True)
            ctx.exit(143)
        except KeyboardInterrupt:
            click.echo("cutkit: interrupted", err=True)
            ctx.exit(130)
        finally:
            if previous is not None:
                signal.signal(signal.SIGTERM, previous[0])
                signal.signal(signal.SIGINT, previous[1])
                sys.unraisablehook = previous_hook


def _set_threads(ctx, param, value):
    """Configure numba's threads before the command runs (``--threads`` or ``CUTKIT_THREADS``)."""
    if not ctx.resilient_parsing:
        from cutkit.threads import configure_threads

        configure_threads(value)
    return value


def _with_threads_option(command):
    """Give ``command`` (and a group's subcommands) the shared ``--threads N`` option."""
    commands = [command] + (list(command.commands.values()) if isinstance(command, click.Group) else [])
    for cmd in commands:
        if not any(p.name == "threads" for p in cmd.params):
            cmd.params.append(click.Option(
                ["--threads"], metavar="N", default=None, expose_value=False, callback=_set_threads,
                help="numba threads (default: $CUTKIT_THREADS, else the free cores, never more than the cores)."))
    return command


def _module_exists(module: str) -> bool:
    return importlib.util.find_spec(module) is not None


@click.group(cls=_TableGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, "--version", prog_name="cutkit")
def cli():
    """cutkit: tetrahedral soft-tissue models from medical volumes, cut with a virtual scalpel."""


def main(argv: list[str] | None = None) -> int:
    """Run the command line and return its exit code."""
    try:
        cli.main(args=argv, prog_name="cutkit", standalone_mode=True)
    except SystemExit as exc:  # click exits through SystemExit
        code = exc.code
        return code if isinstance(code, int) else (0 if code is None else 1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
