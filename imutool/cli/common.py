"""Options and helpers shared by the command modules (loading input, summaries, progress)."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Iterable, Iterator
from typing import Any, TypeVar

import click
import numpy as np

import formats
from formats import Recording
from formats.errors import ImutoolError

T = TypeVar("T")


def input_options(f: Callable) -> Callable:
    """The options every command that reads sensor data accepts."""
    opts = [
        click.option("--columns", default=None, metavar="MAP",
                     help="Foreign CSV column mapping: 'Src=target:unit[*scale],...' (rest inferred)."),
        click.option("--profile", default=None, type=click.Path(exists=True, dir_okay=False),
                     help="TOML sensor profile with the column/unit mapping."),
        click.option("--topic", default=None, help="Bag topic to read (listed when ambiguous)."),
        click.option("--stamp", type=click.Choice(["header", "record"]), default="header", show_default=True,
                     help="Bag time: message header stamp or bag record time."),
        click.option("--duplicates", type=click.Choice(["drop", "mean", "error"]), default="drop",
                     show_default=True, help="Policy for rows sharing a timestamp."),
        click.option("--backwards", type=click.Choice(["error", "sort", "drop"]), default="error",
                     show_default=True, help="Policy for time going backwards."),
        click.option("--mounting", default=None, metavar="REMAP[;R,P,Y]",
                     help="Sensor→body axes, e.g. 'x,-y,-z' or 'y,x,-z;0.5,0,1.2' (misalignment deg)."),
        click.option("--calibration", "calibration_file", default=None,
                     type=click.Path(exists=True, dir_okay=False), help="Calibration TOML to apply."),
    ]
    for o in reversed(opts):
        f = o(f)
    return f


def output_options(f: Callable) -> Callable:
    f = click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")(f)
    f = click.option("--quiet", "-q", is_flag=True, help="No progress or summary output.")(f)
    return f


def load_input(path: str, *, columns: str | None = None, profile: str | None = None, topic: str | None = None,
               stamp: str = "header", duplicates: str = "drop", backwards: str = "error",
               mounting: str | None = None, calibration_file: str | None = None,
               validate: bool = True) -> tuple[Recording, dict[str, Any]]:
    """Read, validate, apply calibration and mounting. Returns (recording, validation report dict)."""
    kind = formats.kind_of(path)
    opts: dict[str, Any] = {}
    if kind == "csv":
        opts = {"columns": columns, "profile": profile}
    elif kind in ("ros1", "ros2"):
        opts = {"topic": topic, "stamp": stamp}
    rec = formats.read(path, **opts)
    report: dict[str, Any] = {}
    if validate:
        rec, rep = rec.validated(duplicates=duplicates, backwards=backwards, source=path)
        report = rep.as_dict()
    if calibration_file:
        from calibration import load_calibration

        rec = load_calibration(calibration_file).apply(rec)
    if mounting:
        remap, mis = formats.parse_mounting(mounting)
        rec = rec.mounted(remap, mis)
    return rec, report


def emit_summary(summary: dict[str, Any], as_json: bool, quiet: bool, lines: Iterable[str] | None = None) -> None:
    """Print the one-screen summary (or JSON) to stdout."""
    if as_json:
        click.echo(json.dumps(summary, indent=2, default=_json_default))
        return
    if quiet:
        return
    for line in lines if lines is not None else _default_lines(summary):
        click.echo(line)


def _default_lines(summary: dict[str, Any], indent: str = "") -> Iterator[str]:
    for k, v in summary.items():
        if isinstance(v, dict):
            yield f"{indent}{k}:"
            yield from _default_lines(v, indent + "  ")
        else:
            yield f"{indent}{k}: {v}"


def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def show_progress(quiet: bool) -> bool:
    return not quiet and sys.stderr.isatty()


def progress(items: Iterable[T], total: int | None, label: str, quiet: bool) -> Iterator[T]:
    """Progress bar on stderr when interactive (quiet or not a TTY: no output)."""
    if not show_progress(quiet):
        yield from items
        return
    with click.progressbar(items, length=total, label=label, file=sys.stderr) as bar:
        yield from bar


def require_channels(rec: Recording, names: Iterable[str], path: str) -> None:
    missing = [n for n in names if n not in rec.channels]
    if missing:
        raise ImutoolError(f"needs channel(s) {', '.join(missing)}; has {', '.join(rec.channels) or 'none'}",
                           path=path)


def parse_vector(text: str, n: int = 3, what: str = "value") -> np.ndarray:
    try:
        v = np.array([float(x) for x in text.split(",")])
    except ValueError:
        raise ImutoolError(f"{what} {text!r}: expected {n} comma-separated numbers") from None
    if v.shape != (n,):
        raise ImutoolError(f"{what} {text!r}: expected {n} comma-separated numbers")
    return v

