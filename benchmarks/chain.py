"""LAAV's own chain against plain Random Voting, stage by stage, on Hopkins155.

For every sequence and seed, in one process and interleaved (so that machine load hits
all alike), this runs plain Random Voting and LAAV under each named configuration
(``--config NAME=field=value,field=value``; the defaults are ``default`` =
``LaavParams()``, ``paper`` = :meth:`laav.LaavParams.paper` and ``no-plain-rv`` =
``LaavParams(rv_select="none")``), and records per run:

* the final error, and the coarse stage's error on the points in atoms (``coarse``);
* whether the fine-tuning converged, its voting iterations (``Voting.n_iterations``:
  every iteration of every trial the call ran) and trials, which candidate it returned;
* whether LAAV's informed trial itself converged and its iterations
  (``informed_converged``, ``informed_iterations``; empty for plain RV and in rows
  written before 2026-12-01);
* seconds of the whole call.

It writes one CSV row per run (``--out``, default ``bench-out/chain.csv``; resumable:
rows already there are kept) and prints, per configuration, the mean error for two /
three / all motions, the worst run, the coarse stage's counts (<= 1 %, > 10 % wrong),
convergence, and the ratios to plain RV's median iterations and median time for two-
and three-motion sequences. The report (``--report``) also names the machine, the date
and the git commit.

    python benchmarks/chain.py [--data DIR] [--seeds 0,1,2,3,4] [--config NAME=k=v,...]
                               [--only GLOB] [--jobs 2] [--out FILE] [--report FILE]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from _machine import cpu_model, git_commit  # noqa: E402 - this folder, on sys.path
from speed import data_dir, truth_files  # noqa: E402

import laav  # noqa: E402

FIELDS = ["config", "sequence", "motions", "seed", "error", "coarse", "coverage", "converged",
          "iterations", "trials", "selected", "seconds", "informed_converged",
          "informed_iterations"]
DEFAULT_CONFIGS = {"default": {}, "paper": "paper", "no-plain-rv": {"rv_select": "none"}}


def make_params(spec) -> laav.LaavParams:
    if isinstance(spec, tuple):  # ("rv", fields): plain Random Voting with these fields
        spec = spec[1]
    return laav.LaavParams.paper() if spec == "paper" else laav.LaavParams(**spec)


def parse_config(text: str) -> tuple[str, object]:
    """``NAME=field=value,field=value`` (or ``NAME=paper``; ``NAME=rv:field=value,...`` runs
    plain Random Voting with those fields instead of LAAV) -> (NAME, spec)."""
    name, _, rest = text.partition("=")
    if not name or not rest:
        raise argparse.ArgumentTypeError(f"--config wants NAME=field=value,..., got {text!r}")
    if rest == "paper":
        return name, "paper"
    if rest.startswith("rv:"):
        return name, ("rv", dict(_assignment(item) for item in rest[3:].split(",") if item))
    return name, dict(_assignment(item) for item in rest.split(","))


def _assignment(text: str) -> tuple[str, object]:
    """``field=value``: an int, a float, true/false, or else the string itself."""
    key, _, raw = text.partition("=")
    for conv in (int, float):
        try:
            return key, conv(raw)
        except ValueError:
            pass
    return key, {"true": True, "false": False}.get(raw.lower(), raw)


_WARM = []


def run_sequence(path: str, seeds: list[int], configs: dict, plain_rv: bool = True) -> list[dict]:
    """Every run for one sequence (plain RV and each configuration, seed by seed)."""
    seq = laav.load_sequence(path)
    if not _WARM:  # first use in this process: lazy imports must not land in a timing
        laav.segment(seq, seq.n_motions)
        laav.random_voting(seq, seq.n_motions)
        _WARM.append(True)
    C = seq.n_motions
    rows = []
    for seed in seeds:
        if plain_rv:
            t = time.perf_counter()
            v = laav.random_voting(seq, C, seed=seed)
            rows.append(_row("plain-rv", seq, seed, v.labels, None, v, time.perf_counter() - t))
        for name, spec in configs.items():
            t = time.perf_counter()
            if isinstance(spec, tuple):  # plain RV under other settings
                v = laav.random_voting(seq, C, make_params(spec), seed=seed)
                rows.append(_row(name, seq, seed, v.labels, None, v, time.perf_counter() - t))
                continue
            res = laav.segment(seq, C, make_params(spec), seed=seed)
            rows.append(_row(name, seq, seed, res.labels, res.coarse.point_labels, res.voting,
                             time.perf_counter() - t))
    return rows


def _row(config, seq, seed, labels, coarse, voting, seconds) -> dict:
    err = laav.misclassification_rate(seq.labels, labels)
    cov = coarse >= 0 if coarse is not None else None
    cerr = (laav.misclassification_rate(seq.labels[cov], coarse[cov])
            if cov is not None and cov.any() else float("nan"))
    return {"config": config, "sequence": seq.name, "motions": seq.n_motions, "seed": seed,
            "error": f"{100 * err:.4f}", "coarse": f"{100 * cerr:.4f}",
            "coverage": f"{cov.mean():.4f}" if cov is not None else "",
            "converged": int(voting.converged), "iterations": voting.n_iterations,
            "trials": voting.n_trials, "selected": voting.selected, "seconds": f"{seconds:.5f}",
            # LAAV's informed trial alone (the paper's Fig. 3 compares it with plain RV);
            # empty for plain RV
            "informed_converged": ("" if voting.informed_converged is None
                                   else int(voting.informed_converged)),
            "informed_iterations": ("" if voting.informed_changed is None
                                    else len(voting.informed_changed))}


def summarise(rows: list[dict]) -> list[str]:
    by = {}
    for r in rows:
        by.setdefault(r["config"], []).append(r)
    rv = {(r["sequence"], str(r["seed"])): r for r in by.get("plain-rv", [])}
    lines = ["| configuration | 2 / 3 / all mean % | worst % | seed range of all-mean (pt) | "
             "coarse <= 1 % / > 10 % (of runs) | converged | iterations / RV (median) | "
             "time / RV median, 2 / 3 motions | LAAV's trial: converged, median iterations |",
             "|---|---|---|---|---|---|---|---|---|"]
    for name, rs in by.items():
        e = np.array([float(r["error"]) for r in rs])
        m = np.array([int(r["motions"]) for r in rs])
        seeds = sorted({int(r["seed"]) for r in rs})
        per_seed = [np.mean([float(r["error"]) for r in rs if int(r["seed"]) == s]) for s in seeds]
        ce = np.array([float(r["coarse"]) for r in rs if r["coarse"] not in ("", "nan")])
        coarse = f"{(ce <= 1).sum()} / {(ce > 10).sum()} of {ce.size}" if ce.size else "-"
        conv = np.mean([int(r["converged"]) for r in rs])
        # the ratios to plain RV over the runs it has rows for (none: --no-plain-rv with an
        # --out that holds none of them; the columns then say so)
        paired = [r for r in rs if (r["sequence"], str(r["seed"])) in rv]
        iters, ratios = "- (no plain-RV rows)", []
        if paired:
            it_p = np.median([int(r["iterations"]) for r in paired])
            it_rv = np.median([int(rv[(r["sequence"], str(r["seed"]))]["iterations"]) for r in paired])
            iters = f"{it_p:.0f} / {it_rv:.0f} = {it_p / max(it_rv, 1):.2f}"
            if len(paired) < len(rs):
                iters += f" (of {len(paired)} runs)"
        for c in (2, 3):
            sub = [r for r in paired if int(r["motions"]) == c]
            every = sum(int(r["motions"]) == c for r in rs)
            if not sub:
                ratios.append("- (no plain-RV rows)" if every else "- (no runs)")
                continue
            t = np.median([float(r["seconds"]) for r in sub])
            t_rv = np.median([float(rv[(r["sequence"], str(r["seed"]))]["seconds"]) for r in sub])
            ratios.append(f"{t / t_rv:.2f} ({1e3 * t:.0f} / {1e3 * t_rv:.0f} ms"
                          + (f", of {len(sub)} runs)" if len(sub) < every else ")"))
        own = [r for r in rs if r.get("informed_iterations") not in (None, "")]
        trial = (f"{100 * np.mean([int(r['informed_converged']) for r in own]):.0f} %, "
                 f"{np.median([int(r['informed_iterations']) for r in own]):.0f}" if own else "-")
        if own and len(own) < len(rs):  # rows of an older run lack the columns
            trial += f" (of {len(own)} runs)"
        lines.append(
            f"| {name} | {e[m == 2].mean():.2f} / {e[m == 3].mean():.2f} / {e.mean():.2f} | "
            f"{e.max():.1f} | {max(per_seed) - min(per_seed):.2f} | {coarse} | {100 * conv:.0f} % | "
            f"{iters} | {' ; '.join(ratios)} | {trial} |")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data")
    ap.add_argument("--seeds", default="0")
    ap.add_argument("--config", action="append", type=parse_config, default=None)
    ap.add_argument("--only", action="append", default=[])
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--out", default="bench-out/chain.csv")
    ap.add_argument("--report", default=None)
    ap.add_argument("--no-plain-rv", action="store_true",
                    help="skip plain RV (its rows are then expected in --out already)")
    args = ap.parse_args(argv)
    configs = dict(args.config) if args.config else dict(DEFAULT_CONFIGS)
    seeds = [int(s) for s in args.seeds.split(",")]
    files = truth_files(data_dir(args.data), args.only)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    done = []
    if out.is_file():
        with open(out, newline="") as fh:
            done = list(csv.DictReader(fh))
    have = {(r["config"], r["sequence"], int(r["seed"])) for r in done}
    wanted = list(configs) if args.no_plain_rv else ["plain-rv", *configs]
    todo = [f for f in files if any((c, f.parent.name, s) not in have for c in wanted for s in seeds)]
    redo = {f.parent.name for f in todo}
    rows = [r for r in done if r["sequence"] not in redo or r["config"] not in wanted]
    with open(out, "w", newline="") as fh:
        w = csv.DictWriter(fh, FIELDS)
        w.writeheader()
        w.writerows(rows)
        with ProcessPoolExecutor(max(1, args.jobs)) as ex:
            for k, new in enumerate(ex.map(run_sequence, [str(f) for f in todo],
                                           [seeds] * len(todo), [configs] * len(todo),
                                           [not args.no_plain_rv] * len(todo))):
                w.writerows(new)
                fh.flush()
                rows += new
                print(f"{k + 1}/{len(todo)} {new[0]['sequence']}", file=sys.stderr, flush=True)
    table = summarise(rows)
    print("\n".join(table))
    if args.report:
        head = [f"# LAAV's chain against plain Random Voting ({time.strftime('%Y-%m-%d %H:%M %Z')})",
                "", f"- Machine: {cpu_model()}, {os.cpu_count()} logical cores, "
                f"{platform.system()} {platform.release()}; one thread per process, "
                f"{args.jobs} process(es)",
                f"- Software: Python {platform.python_version()}, numpy {np.__version__}, "
                f"laav {laav.__version__} (git {git_commit()})",
                f"- Hopkins155: {len({r['sequence'] for r in rows})} sequences, seeds {args.seeds}; "
                f"configurations: {', '.join(f'{k} = {v}' for k, v in configs.items())}",
                "- Times are wall seconds per call, interleaved in one process per sequence; "
                "compare the ratios, not the absolute figures, when the machine is shared.", ""]
        Path(args.report).write_text("\n".join(head + table) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
