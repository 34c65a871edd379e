"""`imutool batch COMMAND INPUTS... -o TEMPLATE`: run any imutool command over many recordings.

The click layer only parses options, builds the jobs and prints; the work is :mod:`imutool.batch`. Each job's
options (``INPUT -o OUTPUT [ARGS]``) are parsed by the command itself; a command with a library route (marked by
:func:`imutool.cli.common.route_of`: every command but capture, selfcheck and batch) then has that route
called directly in the worker (:func:`run_route`, behind the command's own output checks; the summary is the
route's result, no stdout read back). Any other command runs as ``imutool COMMAND ... --json`` through
:func:`imutool.cli.main` with stdout and stderr captured (:func:`run_command`).
"""

from __future__ import annotations

import contextlib
import io
import json
import re
import shlex
import sys
import time
import warnings
from typing import Any

import click

from formats.errors import ImutoolError
from imutool import batch as _batch
from imutool.cli.common import emit_summary
from imutool.progress import bar


def _render_args(argv: list[str], fields: dict[str, str]) -> list[str]:
    out = []
    for a in argv:
        for k, v in fields.items():
            a = a.replace("{" + k + "}", v)
        out.append(a)
    return out


def run_command(argv_template: list[str], job: _batch.Job) -> dict[str, Any]:
    """Run ``imutool <argv>`` for one job in this process; the command's ``--json`` summary, or an ImutoolError
    with the command's one-line error message. Placeholders ``{input}``, ``{output}``, ``{stem}``... are filled."""
    from imutool.cli import main

    fields = {**job.fields, "input": job.input, "output": job.output or ""}
    argv = _render_args(argv_template, fields)
    out, err = io.StringIO(), io.StringIO()
    code: Any = 0
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            main(argv)
        except SystemExit as e:
            code = e.code
    if code not in (0, None):
        lines = [ln for ln in err.getvalue().splitlines() if ln.strip()]
        msg = lines[-1].strip() if lines else f"exit status {code}"
        raise ImutoolError(re.sub(r"^imutool[\w -]*: error: ", "", msg))
    text = out.getvalue()
    try:
        summary = json.loads(text) if text.strip() else {}
    except ValueError:
        summary = {}
    return summary if isinstance(summary, dict) else {"result": summary}


def run_route(words: list[str], argv_template: list[str], job: _batch.Job) -> dict[str, Any]:
    """Run one job through the library route of ``imutool <words>``: the job's options (``argv_template`` with
    ``{input}``, ``{output}``, ``{stem}``... filled) parsed by the command, the route called behind the command's
    output checks (``--force`` as given), nothing printed. Returns the summary ``--json`` prints; a usage error,
    a route's ImutoolError or a report that did not pass (exit status 1) is an ImutoolError."""
    from imutool.cli.common import guarded, json_default

    cmd = _resolve(words)
    call, outputs, append = cmd.imutool_route  # type: ignore[attr-defined]
    fields = {**job.fields, "input": job.input, "output": job.output or ""}
    args = _render_args(argv_template, fields)[len(words) :]
    where = " ".join(["imutool", *words])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # as the command line does without --debug
        try:
            ctx = cmd.make_context(where, args)
        except click.ClickException as e:
            raise ImutoolError(
                " ".join(part.strip() for part in e.format_message().splitlines() if part.strip())
                + (f" (see '{where} --help')" if isinstance(e, click.UsageError) else "")
            ) from None
        with ctx:
            params = {k: v for k, v in ctx.params.items() if k not in ("as_json", "quiet")}
            res = guarded(call, outputs, append)(**params)
    if res.exit_status:
        raise ImutoolError(f"exit status {res.exit_status}")
    return json.loads(json.dumps(res.full_summary(), default=json_default))  # the --json text, as numbers/lists


def _resolve(command: list[str]) -> click.Command:
    from imutool.cli import cli

    ctx = click.Context(cli)
    cmd: click.Command | None = cli
    for word in command:
        if not isinstance(cmd, click.Group):
            break
        cmd = cmd.get_command(ctx, word)
        if cmd is None:
            raise click.UsageError(f"unknown command {' '.join(command)!r} (see 'imutool --help')")
    assert cmd is not None
    return cmd


@click.command(
    "batch",
    context_settings={"ignore_unknown_options": False},
    epilog="Example: imutool batch filter 'voyages/**/*.csv' -o 'est/{rel}/{stem}_est.csv' "
    "--summary est/batch.csv   |   imutool batch convert data/ -o 'pq/{stem}.parquet' --resume",
)
@click.argument("command")
@click.argument("inputs", nargs=-1)
@click.option(
    "-o",
    "--output",
    "template",
    default=None,
    metavar="TEMPLATE",
    help="Output name template: {stem} {name} {ext} {parent} {rel} {index} {input} and manifest columns "
    "(e.g. 'out/{stem}_est.csv'). Omit for commands without an output.",
)
@click.option(
    "--manifest",
    default=None,
    type=click.Path(exists=True, dir_okay=False),
    help="CSV (column 'input', optional 'output' and any fields such as ship, voyage) or TOML ([[job]]).",
)
@click.option(
    "--pattern",
    "patterns",
    multiple=True,
    metavar="GLOB",
    help="Files a folder input contributes (repeatable; default the data extensions: "
    + " ".join(_batch.DATA_PATTERNS)
    + ").",
)
@click.option(
    "--args",
    "extra",
    default="",
    metavar="'OPTIONS'",
    help="Options passed to COMMAND for every input (one quoted string, placeholders allowed).",
)
@click.option(
    "-j",
    "--workers",
    type=click.IntRange(min=1),
    default=None,
    help="Worker processes (default: all usable cores); with --dask the LocalCluster's workers.",
)
@click.option("--dask", "use_dask", is_flag=True, help="Run on a dask.distributed LocalCluster (1 thread/worker).")
@click.option(
    "--scheduler",
    default=None,
    metavar="tcp://HOST:8786",
    help="Run on a running Dask cluster (workers need imutool and the same paths).",
)
@click.option(
    "--resume", is_flag=True, help="Skip inputs whose output is complete (completion marker matches input and output)."
)
@click.option(
    "--force",
    is_flag=True,
    help="Replace existing outputs (passes --force to commands that have it; --resume implies it for "
    "the outputs it redoes).",
)
@click.option(
    "--summary",
    "summary_path",
    default=None,
    metavar="PATH",
    help="Write the per-file table (status, rows, duration, key figures) as .csv or .parquet.",
)
@click.option(
    "--figure",
    "figures",
    multiple=True,
    metavar="KEY",
    help="Key figure from each command's JSON summary (dotted path, repeatable; default: its first numeric values).",
)
@click.option("--dry-run", is_flag=True, help="List the jobs (input → output) and stop.")
@click.option("--json", "as_json", is_flag=True, help="Print totals and per-file results as JSON.")
@click.option("--quiet", "-q", is_flag=True, help="No progress or table (exit status still tells).")
def batch_cmd(
    command: str,
    inputs: tuple[str, ...],
    template: str | None,
    manifest: str | None,
    patterns: tuple[str, ...],
    extra: str,
    workers: int | None,
    use_dask: bool,
    scheduler: str | None,
    resume: bool,
    force: bool,
    summary_path: str | None,
    figures: tuple[str, ...],
    dry_run: bool,
    as_json: bool,
    quiet: bool,
) -> None:
    """Run COMMAND (e.g. filter, convert, events, 'calibrate mag') over INPUTS: files, folders, globs.

    Each input runs as `imutool COMMAND INPUT -o OUTPUT ARGS --json` in its own job; a failing input is listed
    with its error and the others go on. Exit status: 0 all ok (or skipped with --resume), 1 some failed,
    2 the batch itself could not start.
    """
    words = shlex.split(command)
    if not words or words[0] == "batch":
        raise click.UsageError("COMMAND must be an imutool command other than batch")
    cmd = _resolve(words)
    if use_dask and scheduler:
        raise click.UsageError("give --dask (local cluster) or --scheduler ADDRESS, not both")
    try:
        extra_args = shlex.split(extra)
    except ValueError as e:
        raise click.UsageError(f"--args: {e}") from None
    jobs = _batch.make_jobs(inputs, template, manifest, patterns or _batch.DATA_PATTERNS)
    argv = [*words, "{input}"] + (["-o", "{output}"] if template or any(j.output for j in jobs) else [])
    argv += extra_args
    has_json = any(getattr(p, "name", None) == "as_json" for p in cmd.params)
    if has_json and "--json" not in extra_args:
        argv.append("--json")
    has_force = any(getattr(p, "name", None) == "force" for p in cmd.params)
    if has_force and (force or resume) and "--force" not in extra_args:
        argv.append("--force")
    if dry_run:
        for j in jobs:
            args = _render_args(argv, {**j.fields, "output": j.output or ""})
            click.echo(f"{j.input} → {j.output or '-'}   imutool {shlex.join(args)}")
        return
    from functools import partial

    if getattr(cmd, "imutool_route", None) is not None:
        runner = partial(run_route, words, argv)
    else:  # no library route yet: the command line, its stdout read back
        runner = partial(run_command, argv)
    t0 = time.perf_counter()
    with bar("batch", total=len(jobs), unit="file", quiet=quiet or as_json) as b:  # done/total, rate, ETA
        results = _batch.run_batch(
            jobs,
            runner,
            workers=workers,
            scheduler="local" if use_dask else scheduler,
            resume=resume,
            figures=figures or None,
            on_result=lambda r: b.advance(1),
            signature=json.dumps([a for a in argv if a != "--force"]),
        )
    wall = time.perf_counter() - t0
    tot = _batch.totals(results, wall)
    if summary_path:
        _batch.write_summary(results, summary_path)
    if as_json:
        emit_summary(
            {
                "totals": tot,
                "summary_file": summary_path,
                "results": [{k: v for k, v in r.as_dict().items() if k != "summary"} for r in results],
            },
            True,
            False,
        )
    elif not quiet:
        lines = _batch.format_table(results)
        lines.append(
            f"{tot['jobs']} jobs: {tot['ok']} ok, {tot['failed']} failed, {tot['skipped']} skipped "
            f"(complete earlier); {tot['rows']} rows in {tot['wall_seconds']:.1f} s wall"
            + (f"; summary → {summary_path}" if summary_path else "")
        )
        for ln in lines:
            click.echo(ln)
    if tot["failed"]:
        sys.exit(1)
