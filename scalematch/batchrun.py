"""A batch command's run around :mod:`scalematch.batch`'s work: its plan (the CSV, the output
file checked and resumed, the Dask client), its workers (one a core), its lines written with a
progress bar, its last line on stderr and its exit code."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, Dict, Iterator, List, Optional, Tuple

import click

from .config import Config
from .exits import (EXIT_INTERNAL_ERROR, EXIT_INTERRUPTED, EXIT_MATCHED, EXIT_PAIR_ERRORS,
                    InputError)
from .imageio import decoder_stderr_caught
from .outputs import check_not_an_input, check_out_file
from .report import is_terminal, plural, show_progress
from .result import dumps

if TYPE_CHECKING:  # batch imports the pipeline: the command line imports it where used
    from .batch import Counts
    from .batchresume import Plan


def batch_lines(pairs: List[Any], config: Config, max_pixels: int, jobs: int,
                client: Any) -> Iterator[Dict[str, Any]]:
    """The result lines of ``pairs`` from the runner the options ask for."""
    from . import batchdask, batchpool

    if client is not None:
        return batchdask.run_dask(pairs, config, max_pixels, client)
    if jobs == 1 or len(pairs) <= 1:  # decoded here: stderr is ours, the decoders' words caught
        click.get_current_context().with_resource(decoder_stderr_caught())
        return batchpool.run_serial(pairs, config, max_pixels)
    return batchpool.run_pool(pairs, config, max_pixels, jobs)


def available_cores() -> int:
    """The cores this process may run on (its CPU affinity, where the system tells it)."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except (AttributeError, OSError):
        return max(os.cpu_count() or 1, 1)


def workers_for(jobs: int, cores: int) -> Tuple[int, str]:
    """(worker processes, what to say of it): at most one per core. Each match already keeps
    a core busy, so more workers than cores only share them, each holding its images in
    memory (--jobs 64 on 2 cores: about 30 workers, 4.1 GB, and slower, 14.1 s against 9.8 s
    for 30 pairs).

    >>> workers_for(64, 2)
    (2, '--jobs 64: this machine has 2 cores, so 2 worker processes run')
    >>> workers_for(2, 8)
    (2, '')
    """
    if jobs <= cores:
        return jobs, ""
    return cores, (f"--jobs {jobs}: this machine has {cores} {plural(cores, 'core')}, so {cores} worker "
                   f"{'process runs' if cores == 1 else 'processes run'}")


def local_workers(jobs: int, quiet: bool) -> int:
    """The worker processes of ``--jobs``, at most one a core (:func:`workers_for`), said once
    on stderr when fewer than asked (unless ``quiet``)."""
    jobs, note = workers_for(jobs, available_cores())
    if note and not quiet:
        click.echo(note, err=True)
    return jobs


def batch_plan(pairs_csv: Path, output: Optional[Path], retry_errors: bool,
               scheduler: Optional[str], config: Config) -> Tuple[Plan, Any]:
    """The run's ``batchresume.Plan`` and its Dask client (None: local processes). What refuses
    the run is exit 2: the scheduler's address, the CSV, the output file (an input, not
    writable, not a batch output of these options). The output file is changed
    (``batchresume.resume_output``) only once nothing else can refuse the run."""
    from . import batch, batchcsv, batchdask, batchresume

    recorded = batchresume.config_json(config)
    done, retried, client = batchresume.NOTHING_DONE, frozenset(), None
    try:
        if scheduler is not None:  # its form first: a malformed address fails at once
            batchdask.check_scheduler_address(scheduler)
        rows = batchcsv.read_rows(pairs_csv)
        pairs = batchcsv.unique_pairs(rows, pairs_csv.resolve().parent)
        if output is not None:
            check_not_an_input(output, [pairs_csv] + [f for p in pairs
                                                      for f in (p.low_file, p.high_file)],
                               "--output")
            check_out_file(output, "--output")
            done = batchresume.scan_output(output, recorded)
        client = batchdask.connect(scheduler) if scheduler is not None else None
        if output is not None:
            retry = batchresume.errors_to_retry(done, pairs) if retry_errors else frozenset()
            done, retried = batchresume.resume_output(output, done, retry, recorded)
    except batch.BatchError as exc:
        if client is not None:
            client.close()
        raise InputError(str(exc))
    return batchresume.plan_run(len(rows), pairs, done, retried), client


def batch_notes(plan: Plan, pairs_csv: Path, output: Optional[Path]) -> List[str]:
    """What the run says on stderr before it starts: repeated rows, pairs skipped, retried."""
    notes = []
    if not plan.pairs:
        notes.append(f"{pairs_csv} lists no pairs")
    if plan.repeated_rows:
        notes.append(f"rows repeated in {pairs_csv}: {plan.repeated_rows} (each pair is "
                     f"matched once)")
    if plan.skipped:
        notes.append(f"resuming: {plan.skipped} of {len(plan.pairs)} pairs already in {output}")
    if plan.retried:
        n = len(plan.retried)
        notes.append(f"retrying {n} pair{'' if n == 1 else 's'} whose line was an error (removed "
                     f"from {output})")
    return notes


def write_batch(plan: Plan, lines: Iterator[Dict[str, Any]], output: Optional[Path],
                quiet: bool, client: Any) -> Counts:
    """Write each of ``lines`` to ``output`` (appended; stdout when None) as it comes, with a
    progress bar unless ``quiet`` (or the lines go to a terminal: they show the progress); the ``batch.Counts`` of the lines. Ctrl-C exits 130 with how
    many pairs were done. The workers, the file and the Dask ``client`` are closed at the end,
    however it comes."""
    from . import batch

    counts = batch.Counts()
    out_fh = open(output, "a") if output is not None else sys.stdout
    bar = click.progressbar(length=len(plan.todo), label="matching pairs", file=sys.stderr,
                            show_pos=True) if show_progress(quiet) and not (
        output is None and is_terminal(sys.stdout)) else None
    try:
        if bar is not None:
            bar.__enter__()
        for line in lines:
            out_fh.write(dumps(line) + "\n")
            out_fh.flush()
            counts = counts.add(line)
            if bar is not None:
                bar.update(1)
    except KeyboardInterrupt:
        hint = "; run the same command again to resume" if output is not None else ""
        click.echo(f"\ninterrupted: {counts.lines} of {len(plan.todo)} pairs done{hint}",
                   err=True)
        sys.exit(EXIT_INTERRUPTED)
    finally:
        lines.close()  # stops the workers now if the loop ended early
        if bar is not None:
            bar.__exit__(None, None, None)
        if output is not None:
            out_fh.close()
        if client is not None:
            client.close()
    return counts


def batch_summary(plan: Plan, counts: Counts) -> str:
    """The run's last line on stderr: the pairs of this run by verdict, and those done before."""
    before = (f" ({plan.skipped} done before, {plan.errors_before} of them "
              f"{'an error' if plan.errors_before == 1 else 'errors'})" if plan.skipped else "")
    n = len(plan.todo)
    return (f"{n} {plural(n, 'pair')}: {counts.matched} matched, {counts.no_match} no reliable "
            f"match, {counts.errors} {plural(counts.errors, 'error')}"
            f"{f' ({counts.internal} internal)' if counts.internal else ''}{before}")


def batch_exit_code(plan: Plan, counts: Counts) -> int:
    """4 when a pair of this run had an internal error, else 3 when any pair's line is an error
    (this run's or an earlier one's), else 0."""
    if counts.internal:
        return EXIT_INTERNAL_ERROR
    if counts.errors or plan.errors_before:
        return EXIT_PAIR_ERRORS
    return EXIT_MATCHED
