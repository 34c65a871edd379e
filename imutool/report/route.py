"""The routes behind ``imutool report inclinometer`` and ``imutool report heading`` (and ``imutool batch report
...``): load the device under test and the reference, evaluate, write the evidence JSON and PDF, return the summary
and the exit status (0 pass; 1 fail or incomplete: the JSON and PDF are written either way).

    from imutool.report.route import run_inclinometer_report
    res = run_inclinometer_report("dut.csv", "table.csv", "evidence.pdf", test_info="test.toml")
    res.exit_status, res.summary["overall"], res.data["evidence"]["items"]
"""

from __future__ import annotations

import os
from typing import Any

from formats import Recording
from formats.errors import ImutoolError
from formats.jit.warm import CSV_READER, warm_in_background
from imutool.loading import FLAGS, INPUT_ONLY_OPTIONS, MAPPING, how_loaded, split_reference_options
from imutool.refframe import reference_to_ned
from imutool.roll_period import ROLL_KERNEL
from imutool.routes import LOAD_OPTIONS, OnInput, RouteResult, Stage, load_input, load_reference

from .common import sha256_of
from .heading import HeadingOptions, heading_evidence
from .inclinometer import InclinometerOptions, inclinometer_evidence
from .pdf import render_pdf, write_json
from .testinfo import load_test_info


def evidence_paths(output: str | os.PathLike, json_path: str | os.PathLike | None = None) -> tuple[str, str]:
    """(PDF, JSON): the output must end in .pdf; the JSON defaults to the PDF's name with .json."""
    output = os.fspath(output)
    if not output.lower().endswith(".pdf"):
        raise ImutoolError(f"output {output!r} must end in .pdf (the JSON is written beside it)")
    return output, os.fspath(json_path) if json_path is not None else os.path.splitext(output)[0] + ".json"


def identification(device: str | None, config: str | os.PathLike | None) -> dict[str, Any]:
    """The device as declared and its configuration file by sha256 (both optional)."""
    ident: dict[str, Any] = {}
    if device:
        ident["device_declared"] = device
    if config:
        config = os.fspath(config)
        if not os.path.exists(config):
            raise ImutoolError("no such configuration file", path=config)
        ident["configuration_file"] = {"path": config, "sha256": sha256_of(config)}
    return ident


WindowTime = float | str | None
"""A report's ``--start``/``--end``: seconds on the recording's clock, or an ISO 8601 UTC time (a dated
recording only)."""


def window_time(value: WindowTime, rec: Recording, path: str, flag: str) -> float | None:
    """``value`` as recording time (s): a number as it is; an ISO 8601 UTC time (``2014-08-01T12:00:00Z``) through
    the recording's clock (:class:`imutool.clock.Clock`) — refused (ImutoolError) where the recording has no date,
    and where it is neither."""
    from imutool.clock import Clock, parse_utc

    if value is None or (isinstance(value, (int, float)) and not isinstance(value, bool)):
        return None if value is None else float(value)
    text = str(value).strip()
    try:
        return float(text)
    except ValueError:
        pass
    unix = parse_utc(text)
    if unix is None:
        raise ImutoolError(f"{flag} {text!r}: expected seconds or a UTC date and time (e.g. 2014-08-01T12:00:00Z)")
    clock = Clock.of(rec)
    if not clock.dated:
        raise ImutoolError(
            f"{flag} {text}: a UTC clock time, but the recording has no date (its times count from its start); "
            f"give {flag} in seconds",
            path=path,
        )
    return clock.time_of(unix)


def evaluated_window(rec: Recording, t_start: WindowTime, t_end: WindowTime, path: str) -> Recording:
    """``rec`` between ``t_start`` and ``t_end`` (s on the recording's clock, or ISO 8601 UTC times where it has a
    date: :func:`window_time`; None = open); at least 10 samples. A window that ends before it starts or lies
    outside the recording is refused (ImutoolError naming ``path``)."""
    from imutool.clock import Clock

    if t_start is None and t_end is None:
        return rec
    t0 = window_time(t_start, rec, path, "--start")
    t1 = window_time(t_end, rec, path, "--end")
    clock = Clock.of(rec)
    if t0 is not None and t1 is not None and not t1 > t0:
        raise ImutoolError(f"--end {t_end} is not after --start {t_start}", path=path)
    if len(rec) and ((t0 is not None and t0 > rec.time[-1]) or (t1 is not None and t1 < rec.time[0])):
        given = " ".join(f"{f} {v}" for f, v in (("--start", t_start), ("--end", t_end)) if v is not None)
        raise ImutoolError(
            f"{given}: outside the recording ({clock.text(rec.time[0])} … {clock.text(rec.time[-1])} {clock.unit}"
            + (f", {clock.date()}" if clock.dated else f"; {rec.time[0]:.6g} … {rec.time[-1]:.6g} s on its clock")
            + ")",
            path=path,
        )
    out = rec.slice_time(t0, t1)
    if len(out) < 10:
        raise ImutoolError(f"fewer than 10 samples between --start {t_start} and --end {t_end}", path=path)
    out.meta["evaluated_window_s"] = [t0, t1]
    if isinstance(t_start, str) or isinstance(t_end, str):
        out.meta["evaluated_window_utc"] = [clock.iso(t) if t is not None else None for t in (t0, t1)]
    return out


def _load_pair(
    dut: str | os.PathLike | Recording,
    reference: str | os.PathLike | Recording,
    t_start: WindowTime,
    t_end: WindowTime,
    inputs: list[dict[str, Any]],
    strict: bool,
    on_input: OnInput | None,
    load_options: dict[str, Any],
    frame: tuple[str | None, str | None] = (None, None),
) -> tuple[Recording, Recording, str, str]:
    """The DUT (mounting, calibration, the CSV time options and ``--with`` files applied) and the reference (none
    of those: its own clock and header, read with the reference's options ``ref_columns ... ref_with_files``,
    :data:`imutool.loading.REF_LOAD_OPTIONS`; the DUT's column mapping, ``--columns``/``--profile``, unless it is
    given its own, ``ref_columns``/``ref_profile``), windowed; with their names. How each was loaded is in its
    ``meta["loading"]`` (:func:`imutool.loading.how_loaded`). ``frame``: the reference's ``(ref_frame,
    ref_mounting)``, its orientation converted into body FRD → NED (:func:`imutool.refframe.reference_to_ned`; what
    was done in its ``meta["reference_frame"]`` and ``meta["loading"]["frame"]``)."""
    load_options, ref_given = split_reference_options(load_options)
    unknown = set(load_options) - set(LOAD_OPTIONS)
    if unknown:
        raise TypeError(f"unexpected keyword argument(s) {', '.join(sorted(unknown))}")
    if ref_given and isinstance(reference, Recording):
        raise TypeError("the reference's loading options apply to a file, not to a Recording already loaded")
    own_mapping = any(k in ref_given for k in MAPPING)  # --ref-columns/--ref-profile: neither of the DUT's
    ref_options = {
        k: v for k, v in load_options.items() if k not in INPUT_ONLY_OPTIONS and not (own_mapping and k in MAPPING)
    } | ref_given
    inherited = tuple(k for k in MAPPING if ref_options.get(k) and k not in ref_given)
    dut_given = {k: v for k, v in load_options.items() if k in FLAGS and v not in (None, (), [])}
    recs, names = [], []
    for src, opts, given, loader in (
        (dut, load_options, dut_given, load_input),
        (reference, ref_options, ref_given, load_reference),
    ):
        if isinstance(src, Recording):
            recs.append(src)
            names.append(str(src.meta.get("source", "<recording>")))
        else:
            name = os.fspath(src)
            more = {"inherited": inherited} if loader is load_reference else {}
            rec = loader(name, inputs, strict=strict, on_input=on_input, **more, **opts)[0]
            rec.meta["loading"] = how_loaded(rec, given, reference=loader is load_reference)
            recs.append(rec)
            names.append(name)
    if frame[0] is not None or frame[1]:
        ref, done = reference_to_ned(recs[1], frame[0], frame[1], prefixes=("", "ref_"))
        ref.meta["reference_frame"] = done
        if isinstance(ref.meta.get("loading"), dict):
            ref.meta["loading"]["frame"] = done["how"]
        recs[1] = ref
    d = evaluated_window(recs[0], t_start, t_end, names[0])
    r = evaluated_window(recs[1], t_start, t_end, names[1])
    return d, r, names[0], names[1]


def write_evidence(
    ev: dict[str, Any], plots: dict[str, Any], pdf: str, jpath: str, inputs: list[dict[str, Any]]
) -> RouteResult:
    """Write the evidence JSON and PDF; the summary (overall status, lag, every item's status and statistics)
    with the exit status of the evaluation."""
    write_json(ev, jpath)
    pages = render_pdf(ev, plots, pdf)
    summary = {
        "report": ev["report"],
        "pdf": pdf,
        "json": jpath,
        "pages": pages,
        "overall": ev["overall"]["status"],
        "lag_s": ev["alignment"]["lag_s"],
        "items": {it["id"]: {"status": it["status"], **it["stats"]} for it in ev["items"]},
    }
    summary["headline"] = ev["overall"]["headline"]
    summary["exit_status"] = ev["overall"]["exit_status"]
    return RouteResult(summary, inputs, data={"evidence": ev}, exit_status=int(ev["overall"]["exit_status"]))


def run_inclinometer_report(
    dut: str | os.PathLike | Recording,
    reference: str | os.PathLike | Recording,
    output: str | os.PathLike,
    *,
    json_path: str | os.PathLike | None = None,
    options: InclinometerOptions | None = None,
    steps_path: str | None = None,
    dut_channel: str | None = None,
    ref_channel: str | None = None,
    device: str | None = None,
    config: str | os.PathLike | None = None,
    test_info: str | None = None,
    t_start: WindowTime = None,
    t_end: WindowTime = None,
    ref_frame: str | None = None,
    ref_mounting: str | None = None,
    strict: bool = False,
    on_input: OnInput | None = None,
    stage: Stage | None = None,
    **load_options: Any,
) -> RouteResult:
    """Electronic-inclinometer evidence (IMO MSC.363(92), ISO 19697) of ``dut`` against ``reference`` as the PDF
    ``output`` and the JSON ``json_path`` (default beside it). ``options``: every tolerance and tuning constant
    (:class:`InclinometerOptions`); ``steps_path``: CSV of the static heel steps (default detected);
    ``device``, ``config`` (file identified by sha256), ``test_info`` (test record TOML) identify the test;
    ``t_start``/``t_end`` the evaluated window (s on the recordings' clock, or ISO 8601 UTC times where they have a
    date). Paths are loaded with ``load_options`` (:data:`imutool.loading.LOAD_OPTIONS`; the reference without
    mounting, calibration and the DUT's time, header and ``with`` options, but with its own ``ref_rate_hz``,
    ``ref_time_column``, ``ref_header_rows``, ``ref_with_files``, ``ref_with_offsets``; the DUT's column mapping
    unless given its own ``ref_columns``/``ref_profile``). ``ref_frame``/``ref_mounting``: the reference's world
    (``ned``, ``enu``, ``zup``) and body axes, its orientation converted into body FRD → NED at load
    (:func:`imutool.refframe.reference_to_ned`: it needs a quaternion or roll, pitch and heading). ``exit_status``:
    0 PASS, 1 FAIL or INCOMPLETE."""
    pdf, jpath = evidence_paths(output, json_path)
    ident = identification(device, config)
    info = load_test_info(test_info)
    inputs: list[dict[str, Any]] = []
    # a cold cache: a second process compiles the CSV reader's kernel (this command reaches it only after ~1.9 s of
    # imports) and the roll statistics' while this one starts (formats.jit.warm)
    warm_in_background(ROLL_KERNEL, (CSV_READER, ROLL_KERNEL))
    if stage is not None:
        stage("reading")
    d, r, dut_name, ref_name = _load_pair(
        dut, reference, t_start, t_end, inputs, strict, on_input, load_options, (ref_frame, ref_mounting)
    )
    if stage is not None:
        stage("evaluating")
    ev, plots = inclinometer_evidence(
        d,
        r,
        dut_path=dut_name,
        ref_path=ref_name,
        steps_path=steps_path,
        options=options if options is not None else InclinometerOptions(),
        identification=ident,
        dut_channel=dut_channel,
        ref_channel=ref_channel,
        test_info=info,
    )
    if stage is not None:
        stage("writing JSON + PDF")
    return write_evidence(ev, plots, pdf, jpath, inputs)


def run_heading_report(
    dut: str | os.PathLike | Recording,
    reference: str | os.PathLike | Recording,
    output: str | os.PathLike,
    *,
    json_path: str | os.PathLike | None = None,
    options: HeadingOptions | None = None,
    correction_deg: float = 0.0,
    dut_channel: str | None = None,
    ref_channel: str | None = None,
    device: str | None = None,
    config: str | os.PathLike | None = None,
    test_info: str | None = None,
    t_start: WindowTime = None,
    t_end: WindowTime = None,
    ref_frame: str | None = None,
    ref_mounting: str | None = None,
    strict: bool = False,
    on_input: OnInput | None = None,
    stage: Stage | None = None,
    **load_options: Any,
) -> RouteResult:
    """Heading-device evidence (ISO 22090-2 / IMO MSC.116(73): static, dynamic and follow-up error) of ``dut``
    against ``reference`` as the PDF ``output`` and the JSON ``json_path`` (default beside it).
    ``correction_deg`` is added to the DUT heading first (e.g. variation, E +); ``options``: the limits and tuning
    (:class:`HeadingOptions`); the rest as :func:`run_inclinometer_report`."""
    pdf, jpath = evidence_paths(output, json_path)
    ident = identification(device, config)
    info = load_test_info(test_info)
    inputs: list[dict[str, Any]] = []
    if stage is not None:
        stage("reading")
    d, r, dut_name, ref_name = _load_pair(
        dut, reference, t_start, t_end, inputs, strict, on_input, load_options, (ref_frame, ref_mounting)
    )
    if stage is not None:
        stage("evaluating")
    ev, plots = heading_evidence(
        d,
        r,
        dut_path=dut_name,
        ref_path=ref_name,
        dut_channel=dut_channel,
        ref_channel=ref_channel,
        dut_correction_deg=correction_deg,
        options=options if options is not None else HeadingOptions(),
        identification=ident,
        test_info=info,
    )
    if stage is not None:
        stage("writing JSON + PDF")
    return write_evidence(ev, plots, pdf, jpath, inputs)
