"""The ``labauto`` command: one entry point, a subcommand per job.

Errors go to stderr as one line, ``labauto: error: <what was wrong>``, with exit code 1 (2 for a
usage error); ``--debug`` shows the traceback instead.
"""

from __future__ import annotations

import sys

import click

from labauto import __version__
from labauto.cli import process
from labauto.drivers.errors import DeviceError
from labauto.errors import LabautoError


def _print_version(ctx: click.Context, _param: click.Parameter, value: bool) -> None:
    if not value or ctx.resilient_parsing:
        return
    from labauto.vision import kernels

    click.echo(f"labauto, version {__version__}")
    click.echo(kernels.describe())
    ctx.exit()


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.option(
    "--version",
    is_flag=True,
    expose_value=False,
    is_eager=True,
    callback=_print_version,
    help="Show the version and which vision backend runs, and exit.",
)
@click.option("--debug", is_flag=True, help="Show tracebacks instead of one-line errors.")
@click.pass_context
def cli(ctx: click.Context, debug: bool) -> None:
    """labauto: detect colonies on plate images and pick them with a workcell."""
    ctx.ensure_object(dict)
    ctx.obj["debug"] = debug


def _register_commands() -> None:
    from labauto.cli import config_cmd, db, plugins_cmd, run_cmds, vision_cmds
    from labauto.cli.calibrate_cmd import calibrate_group
    from labauto.cli.markers_cmd import markers_group

    cli.add_command(vision_cmds.detect_cmd)
    cli.add_command(vision_cmds.plate_cmd)
    cli.add_command(plugins_cmd.plugins)
    cli.add_command(run_cmds.run_cmd)
    cli.add_command(run_cmds.runs)
    cli.add_command(run_cmds.devices)
    cli.add_command(config_cmd.config_group)
    cli.add_command(db.db)
    cli.add_command(markers_group)
    cli.add_command(calibrate_group)

    from labauto.cli import track_cmd

    cli.add_command(track_cmd.track_cmd)


_register_commands()


def main(argv: list[str] | None = None) -> int:
    """Run the CLI and turn errors into one-line messages and exit codes."""
    args = sys.argv[1:] if argv is None else argv
    debug = "--debug" in args
    try:
        process.configure()
        cli.main(args=args, prog_name="labauto", standalone_mode=False)
    except click.exceptions.Exit as exc:
        return exc.exit_code
    except SystemExit as exc:  # a command's own exit status (e.g. 3: completed with errors)
        return exc.code if isinstance(exc.code, int) else 1
    except click.UsageError as exc:  # one line too, with where to find help
        where = f" (see {exc.ctx.command_path} --help)" if exc.ctx is not None else ""
        click.echo(f"labauto: error: {_one_line(exc.format_message())}{where}", err=True)
        return exc.exit_code
    except click.ClickException as exc:
        click.echo(f"labauto: error: {_one_line(exc.format_message())}", err=True)
        return exc.exit_code
    except click.exceptions.Abort:
        click.echo("labauto: aborted", err=True)
        return 130
    except (LabautoError, DeviceError, ValueError, OSError) as exc:
        if debug:
            raise
        click.echo(f"labauto: error: {_one_line(str(exc))}", err=True)
        return 1
    except KeyboardInterrupt:
        click.echo("labauto: interrupted", err=True)
        return 130
    except Exception as exc:  # cv2.error, RecursionError, MemoryError, OverflowError, ...
        if debug:
            raise
        kind = type(exc).__name__
        if type(exc).__module__ not in ("builtins", None):
            kind = f"{type(exc).__module__.split('.')[0]}.{kind}"  # e.g. cv2.error
        click.echo(
            f"labauto: error: {kind}: {_one_line(str(exc))} (labauto --debug shows the traceback)",
            err=True,
        )
        return 1
    return 0


def _one_line(text: str, limit: int = 500) -> str:
    """The message on one line, at most ``limit`` characters (e.g. cv2.error spans lines)."""
    line = " ".join(text.split()) or "(no message)"
    return line if len(line) <= limit else line[: limit - 3] + "..."


if __name__ == "__main__":
    sys.exit(main())
