"""Soak runs: one selection of pytest items, run again and again, each run with a new seed.

A bench draws new random numbers on every run (tb/harness.py), so a corner that a test reaches
once in a few hundred runs shows up in CI as a rare failure. ``make soak`` runs the selection
``runs`` times, each run with its own ``SEED``, and ends with the seeds that failed and the
command that repeats each::

    make soak TOP=kernels_image SIM=icarus RUNS=20
    python -m tb.soak tb/test_kernels_image.py -k icarus --runs 20 [--jobs 2] [--first-seed N]

The seeds are ``first_seed``, ``first_seed + 1``, ...; without ``--first-seed`` the first is
drawn from the operating system and printed, so a whole soak run can be repeated too. The
items of one run share its seed and run in parallel (``--jobs``); runs follow one another, as
the items of one configuration share a simulator build and its results file.
"""

import argparse
import os
import random
import subprocess
import sys
import time

__all__ = ["soak", "main"]


def soak(pytest_args, seeds, *, jobs=1, python=sys.executable, log=print):
    """Run ``pytest pytest_args`` once per seed; return the seeds whose run failed.

    Parameters
    ----------
    pytest_args : list of str
        What selects the items (files, node ids, ``-k`` expressions).
    seeds : iterable of int
        One run per seed, with ``SEED`` set to it.
    jobs : int
        pytest-xdist workers per run (1: none).
    """
    failed = []
    seeds = list(seeds)
    for n, seed in enumerate(seeds, 1):
        cmd = [python, "-m", "pytest", "-q", *pytest_args]
        cmd += ["-n", str(jobs)] if jobs > 1 else ["-p", "no:xdist"]
        start = time.monotonic()
        proc = subprocess.run(cmd, env={**os.environ, "SEED": str(seed)},
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        tail = [line for line in proc.stdout.splitlines() if line.strip()][-1:]
        summary = tail[0].strip("= ") if tail else "no output"
        if proc.returncode == 5:
            raise ValueError(f"pytest {' '.join(pytest_args)}: no test selected")
        ok = proc.returncode == 0
        if not ok:
            failed.append(seed)
            for line in proc.stdout.splitlines():
                if line.startswith(("FAILED", "ERROR", "E  ")):
                    log(f"    {line[:300]}")
        log(f"run {n}/{len(seeds)} SEED={seed}: {'pass' if ok else 'FAIL'} ({summary}, "
            f"{time.monotonic() - start:.0f} s)")
    return failed


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m tb.soak", allow_abbrev=False,
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=10, help="how many runs (default 10)")
    parser.add_argument("--jobs", type=int, default=1, help="pytest-xdist workers per run")
    parser.add_argument("--first-seed", type=int, default=None,
                        help="seed of the first run (default: drawn and printed)")
    args, pytest_args = parser.parse_known_args(argv)
    if args.runs < 1:
        parser.error(f"--runs {args.runs}: expected at least 1")
    if args.jobs < 1:
        parser.error(f"--jobs {args.jobs}: expected at least 1")
    if not pytest_args:
        parser.error("no pytest selection given (for example tb/test_topic.py -k icarus)")
    first = args.first_seed
    if first is None:
        first = random.SystemRandom().randrange(1 << 31)
    if first < 0:
        parser.error(f"--first-seed {first}: expected a non-negative integer")
    print(f"soak: {args.runs} runs of pytest {' '.join(pytest_args)}, seeds {first}.."
          f"{first + args.runs - 1}", flush=True)
    failed = soak(pytest_args, range(first, first + args.runs), jobs=args.jobs,
                  log=lambda line: print(line, flush=True))
    print(f"soak: {args.runs - len(failed)} of {args.runs} runs passed")
    for seed in failed:
        print(f"  failed with SEED={seed}: SEED={seed} {sys.executable} -m pytest "
              f"{' '.join(pytest_args)}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
