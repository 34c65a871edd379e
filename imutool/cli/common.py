"""Options and helpers shared by the command modules (loading input, summaries, progress)."""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Callable, Iterable, Iterator
from typing import Any, TypeVar

import click
import numpy as np

from formats.errors import ImutoolError
from imutool.loading import load_recording, require_channels  # noqa: F401  (require_channels: re-exported)
from imutool.refframe import REF_FRAMES
from imutool.routes import with_inputs

T = TypeVar("T")


def input_options(f: Callable | None = None, *, rate_flag: str = "--rate") -> Callable:
    """The options every command that reads sensor data accepts (``@input_options``). ``rate_flag``: the name of
    the input's sample-rate option where the command has a ``--rate`` of its own (``@input_options(rate_flag=
    "--input-rate")``)."""
    if f is None:
        return lambda g: _input_options(g, rate_flag)
    return _input_options(f, rate_flag)


def _input_options(f: Callable, rate_flag: str) -> Callable:
    opts = [
        click.option(
            "--columns",
            default=None,
            metavar="MAP",
            help="Foreign CSV column mapping: 'Src=target:unit[*scale],...' (rest inferred).",
        ),
        click.option(
            "--profile",
            default=None,
            type=click.Path(exists=True, dir_okay=False),
            help="TOML sensor profile with the column/unit mapping.",
        ),
        click.option("--topic", default=None, help="Bag topic to read (listed when ambiguous)."),
        click.option(
            "--stamp",
            type=click.Choice(["header", "record"]),
            default=default_of(load_recording, "stamp"),
            show_default=True,
            help="Bag time: message header stamp or bag record time.",
        ),
        click.option(
            "--duplicates",
            type=click.Choice(["drop", "mean", "error"]),
            default=default_of(load_recording, "duplicates"),
            show_default=True,
            help="Policy for rows sharing a timestamp.",
        ),
        click.option(
            "--backwards",
            type=click.Choice(["error", "sort", "drop"]),
            default=default_of(load_recording, "backwards"),
            show_default=True,
            help="Policy for time going backwards.",
        ),
        click.option(
            "--mounting",
            default=None,
            metavar="REMAP[;R,P,Y]",
            help="Sensor→body axes, e.g. 'x,-y,-z' or 'y,x,-z;0.5,0,1.2' (misalignment deg).",
        ),
        click.option(
            "--calibration",
            "calibration_file",
            default=None,
            type=click.Path(exists=True, dir_okay=False),
            help="Calibration TOML to apply.",
        ),
        click.option(
            rate_flag,
            "input_rate_hz",
            type=FiniteFloat(min=0, min_open=True),
            default=None,
            metavar="HZ",
            help="A CSV without a time column: its sample rate; time = n / HZ (n the row from 0), recorded in "
            "the metadata.",
        ),
        click.option(
            "--time-column",
            default=None,
            metavar="NAME[:UNIT]",
            help="The CSV column holding the time, its unit s, ms, us or ns (default: the unit in its name, else "
            "s), e.g. 'Packet time:ms'.",
        ),
        click.option(
            "--header-rows",
            type=click.IntRange(min=1),
            default=None,
            metavar="N",
            help="CSV header rows: the first names the columns, a later one may give units (e.g. RepoIMU: 2). "
            "Default 1, or the profile's header_rows.",
        ),
        click.option(
            "--with",
            "with_files",
            multiple=True,
            type=click.Path(exists=True),
            help="Another recording (a sensor on another clock, e.g. one file per sensor) merged with INPUT: "
            "interpolated onto INPUT's times over the span both cover where the command needs one grid (filter, "
            "heave, calibrate...), kept on its own clock as a stream where it does not (evaluate); which file gave "
            "which channels, and how, is recorded in the metadata. Repeatable; channel names must differ (else "
            "--with-prefix).",
        ),
        click.option(
            "--with-prefix",
            "with_prefixes",
            multiple=True,
            metavar="P",
            help="A prefix for a --with file's channel names (two logs of one kind, e.g. 'imu2_' → imu2_gyro): one "
            "per --with, in order ('' for none).",
        ),
        click.option(
            "--with-offset",
            "with_offsets",
            multiple=True,
            type=FiniteFloat(),
            metavar="S",
            help="Seconds added to a --with file's times (its clock's offset from INPUT's): one per --with, in order.",
        ),
        click.option(
            "--strict",
            is_flag=True,
            expose_value=False,
            callback=_remember_strict,
            help="Input warnings (implausible units or axes, absurd samples, >1 % of rows dropped by "
            "validation) are errors (exit 2).",
        ),
    ]
    for o in reversed(opts):
        f = o(f)
    return f


def reference_options(f: Callable) -> Callable:
    """How a command's reference file (``--reference``) is read, as :func:`input_options` says for its input
    (``@reference_options``; the parameters are the keys of :data:`imutool.loading.REF_LOAD_OPTIONS`, loaded by
    :func:`imutool.routes.load_reference`)."""
    opts = [
        click.option(
            "--ref-columns",
            default=None,
            metavar="MAP",
            help="The reference CSV's column mapping, e.g. 'HeelDeg=roll:deg,TrimDeg=pitch:deg' (as --columns); "
            "with --ref-profile, in place of the input's --columns/--profile (a report's reference otherwise "
            "takes the input's).",
        ),
        click.option(
            "--ref-profile",
            default=None,
            type=click.Path(exists=True, dir_okay=False),
            help="TOML sensor profile with the reference's column/unit mapping (as --profile).",
        ),
        click.option(
            "--ref-rate",
            "ref_rate_hz",
            type=FiniteFloat(min=0, min_open=True),
            default=None,
            metavar="HZ",
            help="A reference CSV without a time column: its sample rate; time = n / HZ (as --rate for the input).",
        ),
        click.option(
            "--ref-time-column",
            default=None,
            metavar="NAME[:UNIT]",
            help="The reference CSV's time column and its unit s, ms, us or ns (as --time-column).",
        ),
        click.option(
            "--ref-header-rows",
            type=click.IntRange(min=1),
            default=None,
            metavar="N",
            help="The reference CSV's header rows: names, then units (as --header-rows).",
        ),
        click.option(
            "--ref-with",
            "ref_with_files",
            multiple=True,
            type=click.Path(exists=True),
            help="Another recording merged onto the reference's times (as --with); repeatable.",
        ),
        click.option(
            "--ref-with-offset",
            "ref_with_offsets",
            multiple=True,
            type=FiniteFloat(),
            metavar="S",
            help="Seconds added to a --ref-with file's times: one per --ref-with, in order.",
        ),
        click.option(
            "--ref-with-prefix",
            "ref_with_prefixes",
            multiple=True,
            metavar="P",
            help="A prefix for a --ref-with file's channel names: one per --ref-with, in order (as --with-prefix).",
        ),
        click.option(
            "--ref-start",
            type=ClockTime(),
            default=None,
            metavar="S|UTC",
            help="Put the reference's first row at this time (its times shifted): s on the input's clock, or a UTC "
            "time (2014-08-01T12:00:00Z) — a reference without a clock (--ref-rate) against a dated input.",
        ),
    ]
    for o in reversed(opts):
        f = o(f)
    return f


def reference_frame_options(f: Callable) -> Callable:
    """``--ref-frame`` and ``--ref-mounting``: the world and body axes of a command's reference orientation
    (parameters ``ref_frame``, ``ref_mounting``; :func:`imutool.refframe.reference_to_ned`)."""
    f = click.option(
        "--ref-mounting",
        default=None,
        metavar="REMAP[;R,P,Y]",
        help="The reference's body axes → the estimate's body axes (as --mounting), e.g. 'x,-y,-z' for a FLU "
        "marker set against an FRD estimate.",
    )(f)
    return click.option(
        "--ref-frame",
        type=click.Choice(list(REF_FRAMES), case_sensitive=False),
        default=None,
        help="The reference's world: ned (as imutool), enu (x east, y north, z up) or zup (a motion-capture volume: "
        "z up, x its own horizontal axis; heading then from that axis). Its orientation is converted into body "
        "FRD → NED before comparing.",
    )(f)


class ClockTime(click.ParamType):
    """A time option: seconds (a number) or an ISO 8601 UTC date and time (``2014-08-01T12:00:00Z``, kept as
    text for the route to put on the recording's clock)."""

    name = "S|UTC"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        from imutool.clock import parse_utc

        if value is None or isinstance(value, float):
            return value
        text = str(value).strip()
        try:
            v = float(text)
        except ValueError:
            if parse_utc(text) is None:
                self.fail(f"{text!r}: expected seconds or a UTC date and time, e.g. 2014-08-01T12:00:00Z", param, ctx)
            return text
        if not np.isfinite(v):
            self.fail(f"{text!r} is not a finite number", param, ctx)
        return v


def output_options(f: Callable) -> Callable:
    f = click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")(f)
    f = click.option("--quiet", "-q", is_flag=True, help="No progress or summary output.")(f)
    return f


def _remember_strict(ctx: click.Context, param: click.Parameter, value: bool) -> bool:
    if value:
        ctx.meta["imutool.strict"] = True
    return value


def strict_requested() -> bool:
    """Whether the running command got ``--strict`` (for a streamed run, which checks its input as it goes)."""
    ctx = click.get_current_context(silent=True)
    return bool(ctx is not None and ctx.meta.get("imutool.strict"))


def note_input(path: str, report: dict[str, Any], strict: bool | None = None) -> None:
    """After a library function loaded ``path`` (report from :func:`imutool.loading.load_recording`): its
    warnings to stderr (an error under ``--strict``), the report kept for the command's summary."""
    _note_input(path, report, list(report.get("warnings") or []), strict)


def _note_input(path: str, report: dict[str, Any], warnings: list[str], strict: bool | None) -> None:
    """Warnings to stderr (or an error under --strict); the report kept for the command's summary."""
    ctx = click.get_current_context(silent=True)
    if strict is None:
        strict = strict_requested()
    if warnings and strict:
        from imutool.loading import strict_message

        raise ImutoolError(strict_message(warnings), path=path)
    for w in warnings:
        click.echo(f"warning: {path}: {w}", err=True)
    if ctx is not None:
        ctx.meta.setdefault("imutool.inputs", []).append({"input": path, **report})


def emit_summary(summary: dict[str, Any], as_json: bool, quiet: bool, lines: Iterable[str] | None = None) -> None:
    """Print the one-screen summary (or JSON) to stdout (with what input validation did, see note_input)."""
    ctx = click.get_current_context(silent=True)
    inputs = ctx.meta.get("imutool.inputs") if ctx is not None else None
    if inputs:
        if lines is None and not as_json:
            lines = list(_default_lines(summary))
        summary = with_inputs(summary, inputs)
        if lines is not None and not as_json:
            lines = [*lines, *_validation_lines(inputs)]
    if as_json:
        click.echo(json.dumps(summary, indent=2, default=json_default))
        return
    if quiet:
        return
    for line in lines if lines is not None else _default_lines(summary):
        click.echo(line)


def _validation_lines(inputs: list[dict[str, Any]]) -> Iterator[str]:
    for r in inputs:
        why = "; ".join(f"{n} {k}" for k, n in r.get("dropped", {}).items())
        bridged = sum(r.get("absurd_samples_interpolated", {}).values()) + sum(
            r.get("absurd_samples_set_nan", {}).values()
        )
        yield (
            f"validation: {r['input']}: {r.get('rows_read', r.get('rows'))} rows read, {r.get('rows_kept')} kept"
            + (f" (dropped: {why})" if why else "")
            + (f"; {bridged} absurd samples bridged" if bridged else "")
            + (
                "; merged onto its times: " + ", ".join(f"{w['input']} ({', '.join(w['channels'])})" for w in r["with"])
                if r.get("with")
                else ""
            )
            + (f"; {len(r['warnings'])} warning(s) on stderr" if r.get("warnings") else "")
        )


def _default_lines(summary: dict[str, Any], indent: str = "") -> Iterator[str]:
    for k, v in summary.items():
        if isinstance(v, dict):
            yield f"{indent}{k}:"
            yield from _default_lines(v, indent + "  ")
        else:
            yield f"{indent}{k}: {v}"


def json_default(o: Any) -> Any:
    """How ``--json`` writes what JSON has no type for: numpy scalars and arrays as numbers and lists, else text."""
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def show_progress(quiet: bool) -> bool:
    return not quiet and sys.stderr.isatty()


def progress(
    items: Iterable[T],
    total: int | None,
    label: str,
    quiet: bool,
    unit: str = "it",
    weight: Callable[[T], int] | None = None,
) -> Iterator[T]:
    """Progress bar on stderr when interactive (quiet or not a TTY: no output); see imutool.progress."""
    from imutool.progress import bar

    with bar(label, total=total, unit=unit, quiet=quiet) as b:
        yield from b.iterate(items, weight)


class LazyBar:
    """A :data:`imutool.progress.Progress` callable for a library function that loads its own input: the bar
    (:func:`imutool.progress.bar`) is drawn at the first progress call, so warnings printed while loading keep a
    clean line. Use as a context manager, like the bar itself."""

    def __init__(self, label: str, unit: str = "it", quiet: bool = False) -> None:
        self.label, self.unit, self.quiet = label, unit, quiet
        self.bar: Any = None

    def __call__(self, done: int, total: int | None = None) -> None:
        if self.bar is None:
            from imutool.progress import bar

            self.bar = bar(self.label, total=total, unit=self.unit, quiet=self.quiet)
        self.bar(done, total)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()

    def __enter__(self) -> LazyBar:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def lazy_bar(label: str, unit: str = "it", quiet: bool = False) -> LazyBar:
    """A progress bar drawn from the first progress call (see :class:`LazyBar`)."""
    return LazyBar(label, unit, quiet)


def parse_vector(text: str, n: int = 3, what: str = "value") -> np.ndarray:
    try:
        v = np.array([float(x) for x in text.split(",")])
    except ValueError:
        raise ImutoolError(f"{what} {text!r}: expected {n} comma-separated numbers") from None
    if v.shape != (n,):
        raise ImutoolError(f"{what} {text!r}: expected {n} comma-separated numbers")
    return v


class FiniteFloat(click.FloatRange):
    """A float option that refuses NaN and ±inf (click's FloatRange lets NaN through every bound check)."""

    name = "float"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        rv = super().convert(value, param, ctx)
        if isinstance(rv, float) and not np.isfinite(rv):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return rv

    def _describe_range(self) -> str:
        if self.min is None and self.max is None:
            return "finite"
        return super()._describe_range()


def safe_outputs(*names: str, append: str | None = None) -> Callable:
    """Decorator for a command that writes files: adds ``--force`` and checks every output before any work.

    ``names``: the command's parameters that name outputs (str, or a tuple for a repeatable option). Every other
    parameter whose value names an existing path is an input: no output may be, or hold, an input (see
    ``formats.atomic``). An existing output file is refused unless ``--force``; with the flag ``append`` set,
    existing ``.toml`` outputs are merged into, not replaced (they must load cleanly; the command checks that).
    Writers inside the command refuse anything the check did not approve.
    """

    def deco(f: Callable) -> Callable:
        return click.option(
            "--force",
            is_flag=True,
            help="Replace existing output files (never an input, never a folder other than a ROS2 "
            "bag folder imutool wrote).",
        )(guarded(f, names, append))

    return deco


def guarded(f: Callable, names: tuple[str, ...], append: str | None = None) -> Callable:
    """``f`` called with its keyword arguments (and ``force``) behind the output checks of :func:`safe_outputs`:
    what the command runs, and what ``imutool batch`` runs around a command's library route."""
    import functools

    from formats.atomic import check_outputs, output_guard

    @functools.wraps(f)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        force = bool(kwargs.pop("force", False))
        outs: list[str] = []
        for n in names:
            v = kwargs.get(n)
            if isinstance(v, (tuple, list)):
                outs += [str(x) for x in v if x]
            elif v:
                outs.append(str(v))
        merging = [o for o in outs if o.lower().endswith(".toml")] if append and kwargs.get(append) else []
        merged = {os.path.realpath(o) for o in merging}
        ins: list[str] = []
        for k, v in kwargs.items():
            if k in names:
                continue
            for x in v if isinstance(v, (tuple, list)) else (v,):
                if isinstance(x, str) and x and os.path.exists(x) and os.path.realpath(x) not in merged:
                    ins.append(x)
        with output_guard(force=force):
            check_outputs(outs, ins, exists_ok=merging)
            try:
                return f(*args, **kwargs)
            except ImutoolError as e:
                if e.path is None and ins and ins[0] not in str(e):  # about the data: name the input
                    raise ImutoolError(str(e), path=ins[0]) from None
                raise

    return wrapper


def route_of(
    call: Callable[..., Any], outputs: tuple[str, ...] = ("output",), append: str | None = None
) -> Callable[[click.Command], click.Command]:
    """Mark a click command as the shell over ``call(**options) -> RouteResult``: the command's parsed options
    (less ``as_json``; ``quiet`` given when ``call`` takes it) → its library route. ``imutool batch`` parses a job's
    options with the command, then runs ``call`` behind the same output checks (``outputs``, ``append``: as
    :func:`safe_outputs`) instead of the command: no stdout to read back."""

    def deco(cmd: click.Command) -> click.Command:
        cmd.imutool_route = (call, tuple(outputs), append)  # type: ignore[attr-defined]
        return cmd

    return deco


def default_of(func: Callable[..., Any], name: str) -> Any:
    """The default of parameter ``name`` of the library function ``func``: a click option takes its default from
    the library route (defaults live once, there)."""
    import inspect

    return inspect.signature(func).parameters[name].default
