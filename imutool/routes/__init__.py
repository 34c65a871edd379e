"""What every command's library route shares: the result it returns, loading its inputs with the report the
command's summary carries, and that summary exactly as ``imutool <command> --json`` prints it.

A library route (:func:`imutool.routes.heave.run_heave`, :func:`imutool.routes.ins.run_ins_track`,
:func:`imutool.nmea_out.run_nmea`, :func:`imutool.routes.zvi.run_zvi`, :func:`imutool.routes.gyrofree.run_gyrofree`,
:func:`imutool.events.run_events` and ``run_fleet``, :func:`imutool.evaluation.run_evaluate`,
:func:`imutool.report.route.run_inclinometer_report` and ``run_heading_report``,
:func:`imutool.convert.run_convert`, :func:`imutool.routes.roll.run_roll`,
:func:`imutool.noise.allan_noise`, :func:`imutool.info.run_info`, :func:`imutool.plot.run_plot`,
:func:`imutool.sim.run_simulate`, the calibration runs of :mod:`imutool.calibrate`; ``run_filter`` returns its own
:class:`imutool.filtering.FilterResult`) takes an input path and the command's options with their defaults, reads,
computes, writes its outputs atomically and returns a :class:`RouteResult`. The click command only parses options,
calls the route and prints; ``imutool batch`` calls the same route. Nothing here prints: an input's warnings go to
``on_input(path, report)`` (the CLI prints them there) and into the result.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from formats import Recording
from formats.errors import ImutoolError
from imutool.loading import LOAD_OPTIONS, load_recording, reference_text, starting_at  # noqa: F401  (LOAD_OPTIONS: re-exported)

OnInput = Callable[[str, dict[str, Any]], None]
"""``on_input(path, report)``: called right after an input is loaded (report from :func:`load_recording`)."""

Stage = Callable[[str], None]
"""``stage(label)``: a route starts its next stage (reading, computing, writing); the CLI's progress bar."""


@dataclass
class RouteResult:
    """What a command's library route produced.

    summary: the command's own summary (rows, key figures, output paths, ``warnings``); inputs: the validation
    report of every input read (``{"input": path, rows read/kept/dropped, warnings...}``); recording: the main
    output when it is a recording; data: the full result when it is not (events: the analysis; reports: the
    evidence); exit_status: what the command exits with (reports: 0 pass, 1 fail or incomplete).
    :meth:`full_summary` is what ``--json`` prints.
    """

    summary: dict[str, Any]
    inputs: list[dict[str, Any]] = field(default_factory=list)
    recording: Recording | None = None
    data: dict[str, Any] | None = None
    exit_status: int = 0

    @property
    def warnings(self) -> list[str]:
        return list(with_inputs(self.summary, self.inputs).get("warnings") or [])

    def full_summary(self) -> dict[str, Any]:
        """The summary with what loading the inputs did (``validation``) and their warnings: the ``--json``."""
        return with_inputs(self.summary, self.inputs)


def load_input(
    path: str | os.PathLike,
    inputs: list[dict[str, Any]],
    *,
    strict: bool = False,
    on_input: OnInput | None = None,
    **load_options: Any,
) -> tuple[Recording, dict[str, Any]]:
    """:func:`imutool.loading.load_recording` of ``path`` (``strict``: its warnings are an ImutoolError); a
    non-empty recording's report is appended to ``inputs`` and passed to ``on_input``."""
    path = os.fspath(path)
    rec, report = load_recording(path, strict=strict, **load_options)
    if len(rec):
        if on_input is not None:
            on_input(path, report)
        inputs.append({"input": path, **report})
    return rec, report


def read_source(
    source: str | os.PathLike | Recording,
    inputs: list[dict[str, Any]],
    *,
    strict: bool = False,
    on_input: OnInput | None = None,
    **load_options: Any,
) -> tuple[Recording, str, dict[str, Any]]:
    """A route's input as (recording, name, loading report): a Recording as it is (named by its ``meta['source']``,
    no report, nothing appended to ``inputs``), a path through :func:`load_input`."""
    if isinstance(source, Recording):
        return source, str(source.meta.get("source", "<recording>")), {}
    name = os.fspath(source)
    rec, report = load_input(name, inputs, strict=strict, on_input=on_input, **load_options)
    return rec, name, report


def load_reference(
    path: str | os.PathLike,
    inputs: list[dict[str, Any]],
    *,
    strict: bool = False,
    on_input: OnInput | None = None,
    inherited: tuple[str, ...] = (),
    **load_options: Any,
) -> tuple[Recording, dict[str, Any]]:
    """:func:`load_input` of a command's second recording, its reference (``evaluate --reference``, the reports'
    ``--reference``): the same loading, its errors naming the reference's flags (``--ref-columns``, ``--ref-rate``,
    ``--ref-with`` ...: :func:`imutool.loading.reference_text`; ``inherited``: the options in ``load_options`` taken
    from the input, e.g. its ``columns``, named by the input's flags); ``start`` (``--ref-start``: seconds on the
    input's clock or an ISO 8601 UTC time) puts its first row there (:func:`imutool.loading.starting_at`)."""
    start = load_options.pop("start", None)
    try:
        rec, report = load_input(path, inputs, strict=strict, on_input=on_input, **load_options)
        if start is not None:
            rec = starting_at(rec, start, os.fspath(path))
    except ImutoolError as e:
        if e.path is None:  # an error about the reference (its mapping ...): name it
            raise ImutoolError(reference_text(str(e), inherited), path=os.fspath(path)) from None
        err = ImutoolError(reference_text(str(e), inherited))
        err.path, err.line = e.path, e.line
        raise err from None
    return rec, report


def with_inputs(summary: dict[str, Any], inputs: list[dict[str, Any]]) -> dict[str, Any]:
    """``summary`` with ``validation`` (each input's report without its plausibility figures; kept when the
    summary has its own) and the inputs' warnings appended to its ``warnings``. Without inputs: ``summary``."""
    if not inputs:
        return summary
    out = dict(summary)
    out.setdefault("validation", [{k: v for k, v in r.items() if k != "plausibility_figures"} for r in inputs])
    warns = [w for r in inputs for w in r.get("warnings", [])]
    if warns:
        have = out.get("warnings")
        out["warnings"] = (list(have) if isinstance(have, (list, tuple)) else [have] if have else []) + warns
    return out
