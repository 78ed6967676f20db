"""The ``hycosim`` application: every command registered, and the console entry point."""

from __future__ import annotations

import inspect
import os
import stat
import sys
from typing import Annotated

import click
import typer

from hycosim.cli.commands import ensemble, examples, fmu, project, results, run
from hycosim.cli.output import err, out, say_error
from hycosim.core import signals
from hycosim.scenario.commands import krl, policy, scene


def _show_version(value: bool) -> None:
    if value:
        from hycosim import __version__  # read from the metadata only when asked (every node process imports this)

        out.print(f"hycosim {__version__}", highlight=False)
        raise typer.Exit()


app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="hycosim: hybrid time/event co-simulation on FMI, relayed over Zenoh.")


@app.callback()
def _options(version: Annotated[bool, typer.Option("--version", callback=_show_version, is_eager=True,
                                                   help="print hycosim's version and exit")] = False) -> None:
    pass


# The commands in the order `hycosim --help` lists them: a project, a run, its results, FMUs,
# then the paper's scenario (its scene, camera, trials, policy and controller).
for commands in (project.app, run.app, results.app, ensemble.app, examples.app, scene.app, policy.app):
    app.add_typer(commands)
app.add_typer(fmu.app, name="fmu")
app.add_typer(scene.scene_app, name="scene")
app.add_typer(krl.app, name="krl")


def _is_option(arg: str) -> bool:
    # "-o" is an option; "-5" is a (negative) angle, left for trials to refuse.
    return arg.startswith("-") and not arg[1:2].isdigit()


def _join_multi_value_options(argv: list[str]) -> list[str]:
    # `--angles 30 40 50 60` as the paper's trials are written; click options take one value.
    out, i = [], 0
    while i < len(argv):
        out.append(argv[i])
        if argv[i] == "--angles":
            values = []
            while i + 1 < len(argv) and not _is_option(argv[i + 1]):
                i += 1
                values.append(argv[i])
            out.append(",".join(values))
        i += 1
    return out


def _is_pipe(fd: int) -> bool:
    try:
        return stat.S_ISFIFO(os.fstat(fd).st_mode)
    except OSError:
        return False


def _help_in_sentences(group: click.Group) -> None:
    """Each command's docstring as paragraphs of whole sentences: rich keeps a docstring's line
    breaks, which then fell mid-sentence in ``--help`` and its list of commands."""
    for command in group.commands.values():
        if command.help:
            paragraphs = [" ".join(p.split()) for p in inspect.cleandoc(command.help).split("\n\n")]
            command.help = "\n\n".join(paragraphs)
            command.short_help = command.short_help or paragraphs[0]
        if isinstance(command, click.Group):
            _help_in_sentences(command)


def main() -> None:
    """Console entry point."""
    import faulthandler

    from hycosim.transport.session import prefer_shared_runtime

    # A model that crashes in native code (an FMU's binary, an extension) kills the process
    # without a word from Python; the fault handler at least prints the stack it was at.
    faulthandler.enable()
    heard: list[int] = []  # the stop signals that came
    signals.raise_on_stop(heard)  # SIGTERM and SIGHUP (a supervisor, a closed terminal) are ways out like Ctrl-C
    prefer_shared_runtime()  # before any session opens; the server and nodes it starts inherit it
    try:
        piped = _is_pipe(1)
        command = typer.main.get_command(app)
        _help_in_sentences(command)
        command(args=_join_multi_value_options(sys.argv[1:]), prog_name="hycosim")
    except SystemExit as exc:
        if exc.code == 1 and piped and not _is_pipe(1):
            # Click ends a command whose stdout pipe closed (`hycosim report RUN | head -1`) with
            # 1, having put /dev/null in its place. The reader went because it had what it
            # wanted: not a failure.
            sys.exit(0)
        # Typer ends a command a stop signal interrupted with 130 whatever the signal; a
        # supervisor's SIGTERM (143) or a closed terminal's SIGHUP (129) is told apart, as
        # the server, the nodes and the launcher tell it.
        stop = signals.stop_behind(exc) if exc.code == 130 else None
        if stop is not None:
            sys.exit(signals.exit_code(stop))
        raise
    except BrokenPipeError:
        # The reader went (`hycosim report RUN | head -1`): it had what it wanted. Nothing more
        # is written, not even the flush at exit, which would raise again.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        sys.exit(0)
    except Exception as exc:
        if heard:  # Ctrl-C while MuJoCo's or torch's extension initialised surfaces as an ImportError
            stop = signals.Stopped(heard[0])
            err.print(signals.describe(stop), highlight=False)
            sys.exit(signals.exit_code(stop))
        if not isinstance(exc, OSError) or exc.filename is None:
            raise
        # The last resort for a file a command could not read or write (an output folder
        # that cannot be made, a PNG path in a missing folder): name it instead of a traceback.
        say_error(f"{exc.filename}: {exc.strerror or exc}")
        sys.exit(2)
