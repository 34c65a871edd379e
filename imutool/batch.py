"""Batch processing: one unit of work per recording, on local cores (process pool) or a Dask cluster.

A batch is a list of :class:`Job` (input path, output path from a naming template, template fields) and a
*runner*: a picklable top-level function ``runner(job) -> dict`` that does the work of one recording and returns
its summary (``rows`` and any key figures). The CLI's runner calls the command's library route (``run_heave``,
``run_zvi``, ...; :mod:`imutool.routes`) as the single command does, or for a command without one the command
line itself; a Python user passes any function of their own (:class:`Call` wraps a route). Nothing here imports
the CLI.

Guarantees (docs/batch.md):

- each job is independent: an exception is recorded as that job's one-line error and the batch goes on;
- a killed run's temporary files (``.<output name>.*.tmp``) are removed before the output is redone;
- completion marker: after a job succeeds its worker writes ``.<output name>.imutool-done.json`` beside the
  output (atomically) with the input's and the output's size and mtime and the job signature (the command line);
  ``resume=True`` skips a job only when that marker exists and still matches both files and the signature, so
  an output half-written when the batch was killed (or an input or the options changed since) is redone;
- execution by :class:`concurrent.futures.ProcessPoolExecutor` (default: all usable cores) or by
  ``dask.distributed`` (``scheduler='tcp://host:8786'`` for a running cluster, ``'local'`` for a LocalCluster);
  no scheduler of our own.
"""

from __future__ import annotations

import csv
import fnmatch
import functools
import glob
import json
import os
import shutil
import socket
import string
import time
import traceback
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from formats.atomic import atomic_path
from formats.errors import ImutoolError
from formats.jit.threads import limit_threads, usable_cores

# what a directory walk picks up by default (a folder holding metadata.yaml is one ROS2 bag)
DATA_PATTERNS = ("*.csv", "*.parquet", "*.pq", "*.bag", "*.mcap", "*.db3", "*.nmea")
MARKER_SUFFIX = ".imutool-done.json"
TEMPLATE_FIELDS = ("input", "stem", "name", "ext", "parent", "rel", "index")


@dataclass
class Job:
    """One unit of work: ``input`` path, ``output`` path (None for commands without an output) and fields.

    ``fields`` are the template fields (stem, name, ext, parent, rel, index, and manifest columns such as ship
    or voyage); they travel with the job to the runner and into the summary table.
    """

    input: str
    output: str | None = None
    fields: dict[str, str] = field(default_factory=dict)


@dataclass
class JobResult:
    """What happened to one job. status: ``ok``, ``failed`` or ``skipped`` (complete from an earlier run)."""

    input: str
    output: str | None
    status: str
    error: str | None = None
    rows: int | None = None
    duration_s: float = 0.0
    figures: dict[str, Any] = field(default_factory=dict)
    summary: dict[str, Any] = field(default_factory=dict)
    fields: dict[str, str] = field(default_factory=dict)
    worker: str = ""
    cpu_s: float = 0.0  # CPU time of the job in its worker (all its threads); with duration_s: its parallelism

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


# -- inputs -----------------------------------------------------------------------------------------------------
def _is_ros2_dir(p: Path) -> bool:
    return p.is_dir() and (p / "metadata.yaml").exists()


def walk(root: str | os.PathLike, patterns: Iterable[str] = DATA_PATTERNS) -> list[tuple[str, str]]:
    """Files under ``root`` (recursively, sorted) matching any pattern → [(path, dir relative to root)].

    Hidden files/folders (names starting with '.', e.g. completion markers and temporary outputs) are skipped;
    a folder holding ``metadata.yaml`` is one ROS2 bag input, not descended into.
    """
    root_p = Path(root)
    pats = tuple(patterns)
    out: list[tuple[str, str]] = []
    for dirpath, dirnames, filenames in os.walk(root_p):
        d = Path(dirpath)
        keep = []
        for name in sorted(dirnames):
            if name.startswith("."):
                continue
            if _is_ros2_dir(d / name):
                out.append((os.fspath(d / name), os.fspath(d.relative_to(root_p))))
            else:
                keep.append(name)
        dirnames[:] = keep
        for name in sorted(filenames):
            if not name.startswith(".") and any(fnmatch.fnmatch(name, p) for p in pats):
                out.append((os.fspath(d / name), os.fspath(d.relative_to(root_p))))
    out.sort()
    return [(p, "" if r == "." else r) for p, r in out]


def read_manifest(path: str | os.PathLike) -> list[dict[str, str]]:
    """Rows of a manifest: CSV with a header (``input`` column required, ``output`` and any other columns
    optional) or TOML with ``[[job]]`` tables. Relative paths are relative to the manifest's folder."""
    p = Path(path)
    if not p.exists():
        raise ImutoolError("no such manifest", path=os.fspath(p))
    rows: list[dict[str, str]]
    if p.suffix.lower() == ".toml":
        try:
            import tomllib
        except ModuleNotFoundError:  # python < 3.11
            import tomli as tomllib  # type: ignore[no-redef]
        try:
            doc = tomllib.loads(p.read_text(encoding="utf-8"))
        except tomllib.TOMLDecodeError as e:
            raise ImutoolError(f"manifest is not valid TOML: {e}", path=os.fspath(p)) from None
        jobs = doc.get("job", doc.get("jobs"))
        if not isinstance(jobs, list) or not all(isinstance(j, dict) for j in jobs):
            raise ImutoolError(
                "TOML manifest needs [[job]] tables (input = '...', other fields optional)", path=os.fspath(p)
            )
        for i, j in enumerate(jobs):
            bad = [k for k, v in j.items() if not isinstance(v, (str, int, float)) or isinstance(v, bool)]
            if bad:
                raise ImutoolError(f"[[job]] {i + 1}: {', '.join(bad)} must be a string or a number", path=os.fspath(p))
        rows = [{str(k): str(v) for k, v in j.items()} for j in jobs]
    else:
        with open(p, newline="", encoding="utf-8-sig") as f:
            rows = [{(k or "").strip(): (v or "").strip() for k, v in r.items()} for r in csv.DictReader(f)]
    for i, r in enumerate(rows):
        if not r.get("input"):
            raise ImutoolError(f"manifest row {i + 1} has no 'input'", path=os.fspath(p))
        for k in ("input", "output"):
            if r.get(k) and not os.path.isabs(r[k]):
                r[k] = os.fspath(p.parent / r[k])
    return rows


def expand_inputs(sources: Iterable[str], patterns: Iterable[str] = DATA_PATTERNS) -> list[tuple[str, str]]:
    """Inputs from files, folders (walked) and glob patterns (``**`` recursive) → [(path, relative dir)]."""
    out: list[tuple[str, str]] = []
    for s in sources:
        if os.path.isdir(s) and not _is_ros2_dir(Path(s)):
            found = walk(s, patterns)
            if not found:
                raise ImutoolError(f"no input files (patterns {', '.join(patterns)}) under this folder", path=s)
            out += found
        elif os.path.exists(s):
            out.append((s, ""))
        elif glob.has_magic(s):
            hits = sorted(glob.glob(s, recursive=True))
            hits = [h for h in hits if not Path(h).name.startswith(".")]
            if not hits:
                raise ImutoolError(f"the pattern {s!r} matches no file")
            out += [(h, "") for h in hits]
        else:
            raise ImutoolError("no such file or folder", path=s)
    seen: set[str] = set()
    uniq = []
    for p, r in out:
        k = os.path.abspath(p)
        if k not in seen:
            seen.add(k)
            uniq.append((p, r))
    return uniq


def template_fields(path: str, rel: str = "", index: int = 0, extra: dict[str, str] | None = None) -> dict[str, str]:
    """Fields for the output template: input, stem, name, ext, parent, rel (folder under the walked root), index."""
    p = Path(path)
    f = {
        "input": path,
        "stem": p.stem,
        "name": p.name,
        "ext": p.suffix.lstrip("."),
        "parent": p.parent.name,
        "rel": rel,
        "index": str(index),
    }
    f.update(extra or {})
    return f


def render(template: str, fields: dict[str, str]) -> str:
    """Fill ``{field}`` placeholders; an unknown field is a clear error listing the known ones."""
    try:
        names = [n for _, n, _, _ in string.Formatter().parse(template) if n is not None]
    except ValueError as e:
        raise ImutoolError(f"output template {template!r}: {e}") from None
    missing = [n for n in names if n not in fields]
    if missing:
        raise ImutoolError(
            f"output template {template!r}: unknown field {{{missing[0]}}}; known: "
            + ", ".join("{" + k + "}" for k in fields)
        )
    return os.path.normpath(template.format(**fields))


def make_jobs(
    sources: Iterable[str] = (),
    template: str | None = None,
    manifest: str | None = None,
    patterns: Iterable[str] = DATA_PATTERNS,
) -> list[Job]:
    """Jobs from inputs (files, folders, globs) and/or a manifest, outputs from the naming template.

    Refused before anything runs: two jobs writing the same output, an output equal to an input.
    """
    items: list[tuple[str, str, dict[str, str]]] = [(p, r, {}) for p, r in expand_inputs(sources, patterns)]
    if manifest:
        for row in read_manifest(manifest):
            extra = {k: v for k, v in row.items() if k not in ("input",)}
            items.append((row["input"], "", extra))
    if not items:
        raise ImutoolError("no inputs: give files, folders, glob patterns or --manifest")
    jobs = []
    for i, (p, rel, extra) in enumerate(items):
        f = template_fields(p, rel, i, {k: v for k, v in extra.items() if k != "output"})
        out = extra.get("output") or (render(template, f) if template else None)
        jobs.append(Job(p, out, f))
    ins = {os.path.abspath(j.input) for j in jobs}
    seen: dict[str, str] = {}
    for j in jobs:
        if j.output is None:
            continue
        k = os.path.abspath(j.output)
        if k in ins:
            raise ImutoolError(f"output {j.output!r} would overwrite an input (check the -o template)")
        if k in seen:
            raise ImutoolError(
                f"inputs {seen[k]!r} and {j.input!r} both map to output {j.output!r}; make the "
                "template unique (e.g. add {rel} or {parent})"
            )
        seen[k] = j.input
    return jobs


# -- completion markers -----------------------------------------------------------------------------------------
def marker_path(output: str) -> Path:
    """``dir/.name.imutool-done.json`` beside ``dir/name``."""
    p = Path(output)
    return p.parent / f".{p.name}{MARKER_SUFFIX}"


def _stamp(path: str) -> dict[str, int] | None:
    try:
        st = os.stat(path)
    except OSError:
        return None
    size = st.st_size
    if os.path.isdir(path):
        size = sum(f.stat().st_size for f in Path(path).rglob("*") if f.is_file())
    return {"size": int(size), "mtime_ns": int(st.st_mtime_ns)}


def is_complete(job: Job, signature: str | None = None) -> dict[str, Any] | None:
    """The stored result if ``job`` completed earlier with the same ``signature`` (e.g. the command line) and
    neither its input nor its output changed since."""
    if job.output is None:
        return None
    m = marker_path(job.output)
    try:
        rec = json.loads(m.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if rec.get("output_stamp") != _stamp(job.output) or rec.get("input_stamp") != _stamp(job.input):
        return None
    if rec.get("signature") != signature:
        return None
    return rec


def remove_stale_temporaries(output: str) -> list[str]:
    """Delete ``.<name>.*.tmp`` left beside ``output`` by a killed earlier run (formats.atomic's temporary names;
    a SIGKILL gives no chance to clean up). Called before a job (re)writes that output."""
    p = Path(output)
    gone = []
    for tmp in p.parent.glob(f".{glob.escape(p.name)}.*.tmp"):
        if tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            tmp.unlink(missing_ok=True)
        gone.append(os.fspath(tmp))
    return gone


def _write_marker(job: Job, result: JobResult, signature: str | None) -> None:
    rec = {
        "input": job.input,
        "output": job.output,
        "signature": signature,
        "input_stamp": _stamp(job.input),
        "output_stamp": _stamp(job.output),
        "result": result.as_dict(),
        "finished": time.time(),
    }
    with atomic_path(marker_path(job.output)) as tmp:  # type: ignore[arg-type]
        tmp.write_text(json.dumps(rec, default=str), encoding="utf-8")


# -- running ----------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Call:
    """A runner calling a library function the way the commands do: ``func(job.input, job.output, **kwargs)``.

    E.g. ``Call(imutool.filtering.run_filter, smooth=True)``, ``Call(imutool.routes.heave.run_heave)``,
    ``Call(imutool.convert.run_convert)``, ``Call(imutool.calibrate.calibrate_mag, method="swing")``. The result's
    ``full_summary()`` (a :class:`imutool.routes.RouteResult`: what the command's ``--json`` prints), else its
    ``summary`` (or the dict returned) is the job's summary. Picklable when ``func`` is a module-level function,
    so it runs in worker processes and on Dask workers alike.
    """

    func: Callable[..., Any]
    kwargs: dict[str, Any] = field(default_factory=dict)

    def __init__(self, func: Callable[..., Any], **kwargs: Any) -> None:
        object.__setattr__(self, "func", func)
        object.__setattr__(self, "kwargs", kwargs)

    def __call__(self, job: Job) -> dict[str, Any]:
        args = (job.input,) if job.output is None else (job.input, job.output)
        res = self.func(*args, **self.kwargs)
        full = getattr(res, "full_summary", None)  # a command route's RouteResult: its --json summary
        summary = full() if callable(full) else getattr(res, "summary", res)
        return dict(summary) if isinstance(summary, dict) else {}


def _one_line(text: str) -> str:
    return " ".join(part.strip() for part in str(text).splitlines() if part.strip())[:500]


def key_figures(summary: dict[str, Any], keys: Iterable[str] | None = None, limit: int = 6) -> dict[str, Any]:
    """Key figures of a summary: the dotted ``keys`` asked for, else the first ``limit`` numeric top-level values."""
    out: dict[str, Any] = {}
    if keys:
        for k in keys:
            v: Any = summary
            for part in k.split("."):
                v = v.get(part) if isinstance(v, dict) else None
            out[k] = v if isinstance(v, (int, float, str, bool)) or v is None else json.dumps(v, default=str)
        return out
    for k, v in summary.items():
        if isinstance(v, (int, float)) and not isinstance(v, bool) and k != "rows":
            out[k] = v
            if len(out) >= limit:
                break
    return out


def execute(
    runner: Callable[[Job], dict[str, Any]],
    job: Job,
    figures: tuple[str, ...] | None = None,
    signature: str | None = None,
) -> JobResult:
    """Run one job in the current process: time it, turn any exception into a one-line error, write the marker."""
    t0, c0 = time.perf_counter(), time.process_time()
    worker = f"{socket.gethostname()}:{os.getpid()}"
    try:
        if job.output:
            Path(job.output).parent.mkdir(parents=True, exist_ok=True)
            remove_stale_temporaries(job.output)
            marker_path(job.output).unlink(missing_ok=True)  # being redone: not complete until it succeeds
        summary = runner(job) or {}
        rows = summary.get("rows", summary.get("rows_out"))
        res = JobResult(
            job.input,
            job.output,
            "ok",
            None,
            int(rows) if isinstance(rows, (int, float)) else None,
            time.perf_counter() - t0,
            key_figures(summary, figures),
            summary,
            dict(job.fields),
            worker,
            time.process_time() - c0,
        )
    except Exception as e:  # one job's failure never stops the batch
        msg = str(e) if isinstance(e, ImutoolError) else f"{type(e).__name__}: {e}"
        if not isinstance(e, ImutoolError) and os.environ.get("IMUTOOL_BATCH_DEBUG"):
            msg += " | " + _one_line(traceback.format_exc())
        return JobResult(
            job.input,
            job.output,
            "failed",
            _one_line(msg) or type(e).__name__,
            duration_s=time.perf_counter() - t0,
            fields=dict(job.fields),
            worker=worker,
        )
    if job.output:
        if not os.path.exists(job.output):
            res.status, res.error = "failed", f"finished but wrote no output {job.output!r}"
            return res
        _write_marker(job, res, signature)
    return res


@dataclass(frozen=True)
class ThreadCapped:
    """A job function run under a thread budget (:func:`formats.jit.threads.limit_threads`) in its worker: N jobs
    at once on C cores get C ÷ N threads each, so their CSV, pyarrow, numba and BLAS pools never oversubscribe.
    ``threads`` None: the Dask worker's usable cores ÷ its threads (a remote cluster's machines are not ours)."""

    fn: Callable[[Job], JobResult]
    threads: int | None

    def __call__(self, job: Job) -> JobResult:
        limit_threads(self.threads or _dask_worker_share())
        return self.fn(job)


def _dask_worker_share() -> int:
    try:
        from dask.distributed import get_worker

        return max(1, usable_cores() // max(1, get_worker().state.nthreads))
    except (ImportError, ValueError, AttributeError):
        return 1


def run_batch(
    jobs: list[Job],
    runner: Callable[[Job], dict[str, Any]],
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    resume: bool = False,
    figures: tuple[str, ...] | None = None,
    on_result: Callable[[JobResult], None] | None = None,
    dask_threads_per_worker: int = 1,
    signature: str | None = None,
) -> list[JobResult]:
    """Run every job; returns results in job order (``on_result`` is called as each one finishes).

    workers: local processes (default all usable cores; 1 runs in this process, no pool). scheduler: None
    (local process pool), ``'local'`` (a dask LocalCluster of ``workers`` processes with
    ``dask_threads_per_worker`` threads each) or a Dask scheduler address ``tcp://host:8786`` (the workers must
    have imutool installed and see the same paths). resume: skip jobs whose completion marker still matches
    (same input and output files, same ``signature`` — the CLI passes the command line, so changed options redo).
    """
    results: list[JobResult | None] = [None] * len(jobs)
    todo: list[int] = []
    for i, job in enumerate(jobs):
        done = is_complete(job, signature) if resume else None
        if done is not None:
            prev = done.get("result", {})
            r = JobResult(
                job.input,
                job.output,
                "skipped",
                None,
                prev.get("rows"),
                0.0,
                prev.get("figures", {}),
                prev.get("summary", {}),
                dict(job.fields),
                prev.get("worker", ""),
            )
            results[i] = r
            if on_result:
                on_result(r)
        else:
            todo.append(i)
    fn = functools.partial(execute, runner, figures=figures, signature=signature)
    for i, r in _dispatch(fn, [jobs[i] for i in todo], todo, workers, scheduler, dask_threads_per_worker):
        results[i] = r
        if on_result:
            on_result(r)
    return [r for r in results if r is not None]


def _dispatch(
    fn: Callable[[Job], JobResult],
    jobs: list[Job],
    index: list[int],
    workers: int | None,
    scheduler: str | None,
    threads: int,
) -> Iterator[tuple[int, JobResult]]:
    if not jobs:
        return
    n = workers or usable_cores()
    if scheduler:
        share = max(1, usable_cores() // (n * max(1, threads))) if scheduler == "local" else None
        yield from _dispatch_dask(ThreadCapped(fn, share), jobs, index, n, scheduler, threads)
        return
    if n <= 1:
        for i, job in zip(index, jobs, strict=True):
            yield i, fn(job)
        return
    n = min(n, len(jobs))
    fn = ThreadCapped(fn, max(1, usable_cores() // n))
    with ProcessPoolExecutor(max_workers=n) as pool:
        pending = {pool.submit(fn, job): i for i, job in zip(index, jobs, strict=True)}
        try:
            while pending:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for fut in done:
                    i = pending.pop(fut)
                    try:
                        yield i, fut.result()
                    except Exception as e:  # the worker process died (killed, out of memory...)
                        job = jobs[index.index(i)]
                        yield (
                            i,
                            JobResult(
                                job.input, job.output, "failed", _one_line(f"worker lost: {e}"), fields=dict(job.fields)
                            ),
                        )
        finally:
            for fut in pending:
                fut.cancel()


def _dask_client(scheduler: str, n: int, threads: int) -> tuple[Any, Any]:
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise ImutoolError("Dask scheduling needs dask.distributed: pip install 'imutool[dask]'") from None
    if scheduler == "local":
        cluster = LocalCluster(n_workers=n, threads_per_worker=threads, processes=True, dashboard_address=None)
        return Client(cluster), cluster
    try:
        return Client(scheduler, timeout="20s"), None
    except (OSError, TimeoutError) as e:
        raise ImutoolError(f"cannot reach the Dask scheduler {scheduler!r}: {_one_line(str(e))}") from None


def _dispatch_dask(
    fn: Callable[[Job], JobResult], jobs: list[Job], index: list[int], n: int, scheduler: str, threads: int
) -> Iterator[tuple[int, JobResult]]:
    from dask.distributed import as_completed

    client, cluster = _dask_client(scheduler, n, threads)
    try:
        futs = client.map(fn, jobs, pure=False, key=[f"imutool-job-{i}-{os.getpid()}-{time.time_ns()}" for i in index])
        where = {f.key: i for f, i in zip(futs, index, strict=True)}
        for fut in as_completed(futs):
            i = where[fut.key]
            try:
                yield i, fut.result()
            except Exception as e:  # lost worker, unpicklable result...
                job = jobs[index.index(i)]
                yield (
                    i,
                    JobResult(
                        job.input,
                        job.output,
                        "failed",
                        _one_line(f"dask: {type(e).__name__}: {e}"),
                        fields=dict(job.fields),
                    ),
                )
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


# -- the summary table ------------------------------------------------------------------------------------------
SUMMARY_COLUMNS = ("input", "output", "status", "rows", "duration_s", "error", "worker")


def summary_rows(results: list[JobResult]) -> tuple[list[str], list[dict[str, Any]]]:
    """Column names and one flat dict per job: fixed columns, manifest fields, then key figures."""
    field_cols: list[str] = []
    fig_cols: list[str] = []
    for r in results:
        for k in r.fields:
            if k not in TEMPLATE_FIELDS and k not in field_cols and k != "output":
                field_cols.append(k)
        for k in r.figures:
            if k not in fig_cols:
                fig_cols.append(k)
    cols = list(SUMMARY_COLUMNS) + field_cols + fig_cols
    rows = []
    for r in results:
        d: dict[str, Any] = {
            "input": r.input,
            "output": r.output or "",
            "status": r.status,
            "rows": r.rows,
            "duration_s": round(r.duration_s, 3),
            "error": r.error or "",
            "worker": r.worker,
        }
        for k in field_cols:
            d[k] = r.fields.get(k, "")
        for k in fig_cols:
            d[k] = r.figures.get(k)
        rows.append(d)
    return cols, rows


def write_summary(results: list[JobResult], path: str | os.PathLike) -> None:
    """The per-job table as CSV (or Parquet by the ``.parquet`` extension), written atomically."""
    cols, rows = summary_rows(results)
    path = os.fspath(path)
    if path.lower().endswith((".parquet", ".pq")):
        try:
            import pyarrow as pa
            import pyarrow.parquet as pq
        except ImportError:
            raise ImutoolError("a Parquet summary needs pyarrow: pip install 'imutool[parquet]'") from None
        data = {}
        for c in cols:
            vals = [r.get(c) for r in rows]
            if all(v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)) for v in vals):
                data[c] = pa.array([None if v is None else float(v) for v in vals], pa.float64())
            else:
                data[c] = pa.array(["" if v is None else str(v) for v in vals], pa.string())
        with atomic_path(path) as tmp:
            pq.write_table(pa.table(data), tmp)
        return
    with atomic_path(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=cols)
        w.writeheader()
        for r in rows:
            w.writerow({k: ("" if v is None else v) for k, v in r.items()})


def format_table(results: list[JobResult], max_width: int = 48) -> list[str]:
    """A fixed-width text table (file, status, rows, duration, figures) for stdout."""
    cols, rows = summary_rows(results)
    show = ["input", "status", "rows", "duration_s"] + [c for c in cols if c not in SUMMARY_COLUMNS]

    def cell(v: Any) -> str:
        if v is None:
            return ""
        if isinstance(v, float):
            return f"{v:.4g}"
        s = str(v)
        return s if len(s) <= max_width else "…" + s[-(max_width - 1) :]

    table = [[cell(r.get(c)) for c in show] for r in rows]
    widths = [max([len(c)] + [len(t[j]) for t in table]) for j, c in enumerate(show)]
    lines = ["  ".join(c.ljust(w) for c, w in zip(show, widths, strict=True))]
    lines += ["  ".join(v.ljust(w) for v, w in zip(t, widths, strict=True)) for t in table]
    for r in results:
        if r.status == "failed":
            lines.append(f"FAILED {r.input}: {r.error}")
    return lines


def totals(results: list[JobResult], wall_s: float) -> dict[str, Any]:
    """Counts per status, rows, job time and wall time."""
    c = {s: sum(r.status == s for r in results) for s in ("ok", "failed", "skipped")}
    ran = [r for r in results if r.status != "skipped"]
    return {
        "jobs": len(results),
        **c,
        "rows": sum(r.rows or 0 for r in results if r.status == "ok"),
        "job_seconds": round(sum(r.duration_s for r in ran), 3),
        "job_cpu_seconds": round(sum(r.cpu_s for r in ran), 3),
        "wall_seconds": round(wall_s, 3),
    }
