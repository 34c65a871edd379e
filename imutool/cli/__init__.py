"""The imutool command line: a thin click shell over the library.

Commands are loaded lazily from ``imutool.cli.<module>`` so start-up stays fast and each capability owns
its own command module. Errors are one line on stderr (exit status 2) unless ``--debug`` is given.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys

import click

from imutool import __version__

# command name -> (module under imutool.cli, attribute, one-line help shown in `imutool --help`)
COMMANDS: dict[str, tuple[str, str, str]] = {
    "info": ("info", "info_cmd", "Summarise a recording: duration, rate, gaps, channels, units, ranges."),
    "convert": ("convert", "convert_cmd", "Convert between CSV, Parquet, ROS1/ROS2 bags and NMEA 0183."),
    "plot": ("plot", "plot_cmd", "Plot channels of a recording to PNG/PDF."),
    "simulate": ("simulate", "simulate_cmd", "Simulate a recording with truth columns (ref_*)."),
    "filter": ("filter", "filter_cmd", "Estimate roll/pitch/heading: quaternion EKF, compass KF, baselines."),
    "evaluate": ("evaluate", "evaluate_cmd", "Compare estimates with a reference: RMSE, max, lag, SNR."),
    "calibrate": ("calibrate", "calibrate_group", "Calibrate magnetometer, deviation, gyro, accelerometer."),
    "allan": ("allan", "allan_cmd", "Allan deviation: ARW/VRW, bias instability, rate random walk."),
    "heave": ("heave", "heave_cmd", "Heave from acceleration: real-time and delayed."),
    "zvi": ("zvi", "zvi_cmd", "Detect zero-velocity intervals (paper, SHOE, ARE, MV, MAG)."),
    "ins": ("ins", "ins_cmd", "Strapdown INS with error-state EKF and zero-velocity updates."),
    "gyrofree": ("gyrofree", "gyrofree_cmd", "Angular rate and attitude from an accelerometer array."),
    "roll": ("roll", "roll_cmd", "Roll statistics per MSC.363(92): heel, period, amplitudes, peak hold."),
    "report": ("report", "report_group", "Certification evidence reports (inclinometer, heading device)."),
    "nmea": ("nmea", "nmea_cmd", "Write NMEA 0183 sentences (HRM, XDR, HDG, THS) to a file or port."),
    "capture": ("capture", "capture_group", "Record serial NMEA, bridge frames, I2C or Modbus sensors."),
    "live": ("live", "live_cmd", "Live inclinometer: IMU in, HRM/XDR/PASHR/TSS1/THS/ROT out to serial, UDP, TCP."),
    "events": ("events", "events_group", "Heavy-roll events, hourly roll statistics, parametric roll; fleet table."),
    "batch": ("batch", "batch_cmd", "Run any command over many files on local cores or a Dask cluster."),
    "selfcheck": ("selfcheck", "selfcheck_cmd", "Compile every kernel once and check a tiny end-to-end run."),
}


def _available(name: str) -> bool:
    mod = COMMANDS[name][0]
    return importlib.util.find_spec(f"imutool.cli.{mod}") is not None


class LazyGroup(click.Group):
    """A click group whose sub-commands are imported on first use."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return [n for n in COMMANDS if _available(n)]

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name not in COMMANDS or not _available(name):
            return None
        mod, attr, _ = COMMANDS[name]
        from imutool.cli.ranges import apply_ranges  # every numeric option: declared range, no NaN/inf

        return apply_ranges(getattr(importlib.import_module(f"imutool.cli.{mod}"), attr), name)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = [(n, COMMANDS[n][2]) for n in self.list_commands(ctx)]
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)


@click.group(
    cls=LazyGroup,
    context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100},
    epilog="Example: imutool simulate ship-roll -o roll.csv && imutool filter roll.csv -o est.csv",
)
@click.version_option(__version__, prog_name="imutool")
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def cli(ctx: click.Context, debug: bool) -> None:
    """imutool — marine inertial sensors: capture, calibrate, reprocess, report.

    Units inside are SI; angles are degrees at every user-facing surface. Body frame FRD (x bow,
    y starboard, z down), world frame NED, quaternions [w,x,y,z] body→NED.
    """
    ctx.ensure_object(dict)
    ctx.obj["debug"] = debug


def main(argv: list[str] | None = None) -> None:
    """Console entry point: runs the CLI and turns errors into one clear line (exit status 2)."""
    from formats.errors import ImutoolError

    args = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in args
    if not debug:  # numpy's RuntimeWarnings (overflow, empty slice...) are no message for a user
        import warnings

        warnings.simplefilter("ignore", RuntimeWarning)
    try:
        try:
            cli.main(args=args, prog_name="imutool", standalone_mode=False)
        finally:
            _close_progress()
    except click.exceptions.Abort:
        click.echo("imutool: aborted", err=True)
        sys.exit(130)
    except click.exceptions.NoArgsIsHelpError as e:  # a bare `imutool` or `imutool calibrate`: the help
        click.echo(e.ctx.get_help() if e.ctx is not None else e.format_message())
        sys.exit(0)
    except click.ClickException as e:  # usage errors (missing argument, bad choice/type, unknown option): one line
        ctx = getattr(e, "ctx", None)
        where = ctx.command_path if ctx is not None else _command_path(args)
        click.echo(
            f"{where}: error: {_one_line(e.format_message())}"
            + (f" (see '{where} --help')" if isinstance(e, click.UsageError) else ""),
            err=True,
        )
        sys.exit(2)
    except ImutoolError as e:
        if debug:
            raise
        click.echo(f"{_command_path(args)}: error: {_one_line(str(e))}", err=True)
        sys.exit(2)
    except KeyboardInterrupt:
        click.echo("imutool: interrupted", err=True)
        sys.exit(130)
    except BrokenPipeError:
        sys.exit(0)
    except Exception as e:  # an unexpected failure: still one line, the traceback with --debug
        if debug:
            raise
        click.echo(f"imutool: internal error: {type(e).__name__}: {e} (run with --debug for details)", err=True)
        sys.exit(3)
    sys.exit(0)


FAST_EXIT_ENV = "IMUTOOL_FAST_EXIT"


def run() -> None:
    """The ``imutool`` executable: :func:`main`, then the process ends without Python's teardown of its modules.

    Tearing down numba's and LLVM's objects took ~0.15 s of every command on the project's 2-core machine (a
    2 000-row ``filter``: 0.18 s from the command's end to the process's, 0.03 s without), after the outputs are
    closed. What Python's exit does before that teardown is done here: the other non-daemon threads joined, the
    ``atexit`` handlers run (logging, multiprocessing's children, a temporary kernel folder), stdout and stderr
    flushed; the exit status is :func:`main`'s. An exception other than ``SystemExit`` (``--debug``) leaves the
    ordinary way. ``IMUTOOL_FAST_EXIT=0``: Python's own exit. :func:`main` itself (tests, ``python -c``) is
    unchanged."""
    import os

    try:
        main()
        code: object = 0
    except SystemExit as e:
        code = e.code
    if os.environ.get(FAST_EXIT_ENV, "1").strip() == "0":
        sys.exit(code)
    _exit_now(code)


def _exit_now(code: object) -> None:
    """End the process with ``code`` (a ``SystemExit`` code) as Python's exit would, without its module teardown."""
    import atexit
    import os
    import threading

    if code is None:
        status = 0
    elif isinstance(code, int):
        status = code
    else:  # sys.exit("message"): said on stderr, status 1
        print(code, file=sys.stderr)
        status = 1
    # Python's own order: threading's exit hooks (a thread pool told to stop) and the non-daemon threads joined,
    # then the atexit handlers
    shutdown = getattr(threading, "_shutdown", None)
    if shutdown is not None and threading.current_thread() is threading.main_thread():
        shutdown()
    else:
        for t in threading.enumerate():
            if t is not threading.current_thread() and not t.daemon:
                t.join()
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (BrokenPipeError, ValueError):  # a closed pipe (`imutool ... | head`): nothing more to say
            pass
        except OSError as e:  # (a full disk): not a success, as Python's own exit says (status 120)
            status = status or 120
            if stream is sys.stdout:
                try:
                    print(f"imutool: the standard output could not be written: {e}", file=sys.stderr, flush=True)
                except (OSError, ValueError):
                    pass
    os._exit(status & 0xFF)  # (as the system keeps it: sys.exit(-1) is 255)


def _one_line(text: str) -> str:
    """A message folded onto one line (click's messages may hold newlines)."""
    return " ".join(part.strip() for part in str(text).splitlines() if part.strip())


def _command_path(args: list[str]) -> str:
    """'imutool', 'imutool filter' or 'imutool calibrate mag' from the command-line arguments."""
    words = ["imutool"]
    rest = [a for a in args if not a.startswith("-")]
    if rest and rest[0] in COMMANDS:
        words.append(rest[0])
        group = COMMANDS[rest[0]][1].endswith("_group")
        if group and len(rest) > 1 and rest[1].isidentifier():
            words.append(rest[1])
    return " ".join(words)


def _close_progress() -> None:
    """Close any progress bar left open (an error line must start on a clean line)."""
    mod = sys.modules.get("imutool.progress")
    if mod is not None:
        mod.close_all()
