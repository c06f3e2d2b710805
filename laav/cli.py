"""The ``laav`` command: segment one sequence, run the Hopkins155 benchmark, redo a report.

::

    laav segment FILE [--motions C|auto] [--method laav|rv] [--seed S] [--out labels.csv]
    laav bench --data DIR [--methods laav,rv] [--seeds N] [--noise 0,0.5,1,2]
               [--missing 0,0.2,0.4] [--only GLOB]
               [--jobs N] [--scheduler tcp://HOST:PORT] [--out DIR]
    laav report DIR
    laav convert IN OUT [--format hopkins|kt3d|npz|csv] [--complete-only]
    laav track VIDEO [-o tracks.npz] [--max-points N] [--min-length L] [--stride S] ...
    laav --version

``--param key=value`` (repeatable, ``segment`` and ``bench``) sets any field of
:class:`laav.LaavParams`, e.g. ``--param rv_max_iter=50 --param lam=3``.

Exit codes: 0 success, 1 some benchmark runs failed, 2 bad input (unreadable sequence,
bad option, missing number of motions, fewer tracks than 8 per motion, a path that cannot be
read or written, a video that cannot be opened or gives no usable tracks: one line on
stderr; LAAV's warnings also print as one line, ``laav CMD: warning: ...``), 130 interrupted.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import os
import sys
from pathlib import Path

from .params import PRESETS

__all__ = ["main", "build_parser", "add_track_arguments", "track_options", "TRACK_OPTIONS"]


class _UsageError(Exception):
    pass


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return v


def _seed(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer in [0, 2**63), got {text!r}") from None
    if not 0 <= v < 2**63:
        raise argparse.ArgumentTypeError(f"expected an integer in [0, 2**63), got {text!r}")
    return v


def _jobs(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if v == 0:
        raise argparse.ArgumentTypeError("expected a positive number of processes, or a negative "
                                         "one as in joblib (-1: all cores), got 0")
    return v


def _motions(text: str):
    if text.strip().lower() == "auto":
        return "auto"
    try:
        return _positive_int(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"expected a positive integer or 'auto', got {text!r}") from None


def _param_help() -> str:
    return ("set a LaavParams field, e.g. --param rv_max_iter=50 (repeatable; numbers, "
            "true/false and none are converted)")


def _add_max_points(parser: argparse.ArgumentParser) -> None:
    from .io import MAX_POINTS

    parser.add_argument("--max-points", type=_positive_int, default=None, metavar="N",
                        help=f"refuse sequences with more than N points (default {MAX_POINTS:,}; "
                             "time and memory grow about linearly; docs/bench/scale.md)")


def build_parser() -> argparse.ArgumentParser:
    from . import __version__

    parser = argparse.ArgumentParser(
        prog="laav",
        description="Motion segmentation of tracked trajectories by Locally Affine Atom Voting.",
    )
    parser.add_argument("--version", action="version", version=f"laav {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    seg = sub.add_parser(
        "segment", help="segment one sequence and write its labels",
        description="Segment the trajectories of one sequence (Hopkins155 *_truth.mat, "
                    "KT3DMoSeg .mat, .npz, tracks .csv, or a folder holding one) and write the "
                    "labels as CSV (point,label). With "
                    "ground truth in the file, also print the misclassification rate.")
    seg.add_argument("file", metavar="FILE", help="sequence file (.mat / .npz / .csv) or its folder")
    seg.add_argument("--motions", "-C", type=_motions, metavar="C",
                     help="number of motions, or auto to estimate it (default: from the file's "
                          "ground truth)")
    seg.add_argument("--method", choices=("laav", "rv"), default="laav",
                     help="LAAV (default) or plain Random Voting")
    seg.add_argument("--seed", type=_seed, default=None, metavar="S",
                     help="random seed, an integer in [0, 2**63) (default: the --params file's "
                          "seed, else 0)")
    seg.add_argument("--out", "-o", metavar="CSV",
                     help="labels file, or folder to write it in (an existing one, or a path ending "
                          "in /: created) (default: <input file's name>_labels.csv in the current "
                          "folder, without a Hopkins155 _truth suffix, reduced to letters, digits "
                          "and _.+-; two track files from one video get two labels files)")
    seg.add_argument("--preset", choices=tuple(PRESETS), default="default",
                     help="parameters to start from: default (ours), paper (every stage as the "
                          "LAAV paper writes it, LaavParams.paper()) or with-plain-rv (ours with "
                          "plain RV beside LAAV's trial, LaavParams.with_plain_rv()); own-chain "
                          "is the default's chain, LaavParams.own_chain(); --param changes them")
    seg.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                     help=_param_help())
    seg.add_argument("--params", metavar="JSON",
                     help="parameters from a params file (the explorer's Parameters (JSON) export, "
                          "or a {field: value} object; its seed and C are not used), applied to "
                          "the preset; --param changes them further")
    seg.add_argument("--check", action="store_true",
                     help="also run plain Random Voting (random starts, the same parameters, C and "
                          "seed) and print on how many points the two labellings differ; above 10 %% "
                          "a warning says at least one of them is wrong on half that share or more "
                          "(the explorer's check on tracks without ground truth; about twice the time)")
    _add_max_points(seg)
    _add_complete_only(seg)

    bench = sub.add_parser(
        "bench", help="run the benchmark over a Hopkins155-style folder",
        description="Run every sequence x method x seed x noise level of a Hopkins155-style "
                    "folder (<seq>/<seq>_truth.mat), append one row per run to OUT/runs.csv, "
                    "and write OUT/report.md with figures. Rerunning with the same --out "
                    "skips runs already in runs.csv.")
    bench.add_argument("--data", required=True, metavar="DIR", help="Hopkins155-style folder")
    bench.add_argument("--methods", default="laav,rv",
                       help="comma-separated methods among laav, rv (default laav,rv)")
    bench.add_argument("--seeds", type=_positive_int, default=1, metavar="N",
                       help="seeds 0..N-1 per sequence, method and noise level (default 1)")
    bench.add_argument("--noise", default="0", metavar="LIST",
                       help="comma-separated pixel noise levels sigma (default 0), e.g. 0,0.5,1,2")
    bench.add_argument("--missing", default="0", metavar="LIST",
                       help="comma-separated shares in [0, 0.95) of the entries to hide with the "
                       "seeded occlusion model (tracks start late, end early, one gap; after the "
                       "noise); default 0 (complete data), e.g. 0,0.2,0.4,0.6")
    bench.add_argument("--only", action="append", default=[], metavar="GLOB",
                       help="only sequences whose name matches the glob (repeatable, or "
                            "comma-separated)")
    bench.add_argument("--jobs", "-j", type=_jobs, default=None, metavar="N",
                       help="worker processes (default: all cores; negative as in joblib)")
    bench.add_argument("--scheduler", metavar="ADDRESS",
                       help="run on a Dask distributed cluster, e.g. tcp://10.0.0.5:8786")
    bench.add_argument("--out", "-o", default="bench-out", metavar="DIR",
                       help="output folder (default bench-out)")
    bench.add_argument("--preset", choices=tuple(PRESETS), default="default",
                       help="parameters to start from: default (ours), paper (LaavParams.paper()), "
                            "with-plain-rv (LaavParams.with_plain_rv()) or own-chain (the default's "
                            "chain, LaavParams.own_chain()); --param changes them")
    bench.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                       help=_param_help())
    _add_max_points(bench)
    bench.add_argument("--no-report", action="store_true",
                       help="only write runs.csv (make the report later with `laav report`)")
    bench.add_argument("--allow-mixed", action="store_true",
                       help="resume an --out folder whose runs were made by another git commit or "
                            "version (refused by default; every row records its code)")
    bench.add_argument("--quiet", "-q", action="store_true", help="no progress bar")

    rep = sub.add_parser("report", help="(re)write report.md and figures from a runs.csv",
                         description="Write DIR/report.md and its figures from DIR/runs.csv.")
    rep.add_argument("dir", metavar="DIR", help="bench output folder holding runs.csv")
    _add_convert(sub)
    _add_track(sub)
    return parser


def _add_complete_only(parser: argparse.ArgumentParser, segment: bool = True) -> None:
    parser.add_argument("--complete-only", action="store_true",
                        help=("keep only the tracks visible in every frame (without it, tracks with "
                              "missing entries are segmented too, those seen too briefly labelled "
                              "-1); output rows keep the file's point numbers (a tracks CSV's "
                              "track ids)") if segment else
                        "keep only the tracks visible in every frame (without it every track is "
                        "written, missing entries included)")


def _add_convert(sub) -> None:
    from .io import FORMATS

    conv = sub.add_parser(
        "convert", help="convert a sequence file to another format",
        description="Read a sequence (Hopkins155 or KT3DMoSeg .mat, .npz, tracks CSV; format "
                    "from the content) and write it as OUT, in the format its extension names "
                    "(.npz, .csv, .mat: Hopkins155 when complete, else KT3DMoSeg) or --format.")
    conv.add_argument("input", metavar="IN", help="sequence file or its folder")
    conv.add_argument("output", metavar="OUT", help="file to write")
    conv.add_argument("--format", choices=FORMATS, default=None,
                      help="output format (default: from OUT's extension)")
    _add_complete_only(conv, segment=False)
    _add_max_points(conv)


def _load_for_command(args):
    """The sequence of ``args.file``/``args.input``, with ``--complete-only`` applied.

    Returns ``(seq, kept)``: ``kept`` the file's indices of ``seq``'s points (None: all).
    """
    from . import SequenceError, load_sequence
    from .io import layout_warning

    path = getattr(args, "file", None) or args.input
    try:
        seq = load_sequence(path, isolated=True, max_points=args.max_points)
        hint = layout_warning(seq)
        if hint:
            print(f"laav {args.command}: warning: {hint}", file=sys.stderr)
        if not args.complete_only or seq.is_complete:
            return seq, None
        full, kept = seq.complete()
    except SequenceError as exc:
        raise _UsageError(str(exc)) from None
    print(f"--complete-only: kept {kept.size} of {seq.n_points} points (those visible in every "
          f"frame; {100 * (1 - seq.visible_share):.1f} % of the entries were missing)", file=sys.stderr)
    return full, kept


def _cmd_convert(args) -> int:
    from . import SequenceError, save_sequence

    given = str(args.output)
    if not given.strip():
        raise _UsageError("OUT is empty: give a file name (.npz, .mat or .csv)")
    if _names_a_folder(given):
        raise _UsageError(f"{given}: names a folder; give a file name (.npz, .mat or .csv)")
    seq, _ = _load_for_command(args)
    try:
        _output_path(given, "")  # its folders, as segment's and track's --out
        out = save_sequence(seq, args.output, args.format)
    except SequenceError as exc:
        raise _UsageError(str(exc)) from None
    vis = "" if seq.is_complete else f", {100 * seq.visible_share:.1f} % visible"
    print(f"wrote {out} ({seq.n_frames} frames, {seq.n_points} points{vis})")
    return 0


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not v > 0 or v == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return v


def _int_at_least(lo: int):
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer >= {lo}, got {text!r}") from None
        if v < lo:
            raise argparse.ArgumentTypeError(f"expected an integer >= {lo}, got {text!r}")
        return v

    return parse


#: The tracker's options, shared by ``laav track`` and ``laav-explore VIDEO``:
#: (flag, keyword of :func:`laav.track.track`, argparse keywords).
TRACK_OPTIONS = (
    ("--max-points", "max_points", dict(type=_positive_int, default=1000, metavar="N",
                                        help="most tracks alive at once (default 1000)")),
    ("--max-tracks", "max_tracks", dict(type=_positive_int, default=None, metavar="N",
                                        help="keep only the N longest tracks (default: all)")),
    ("--min-length", "min_length", dict(type=_int_at_least(2), default=5, metavar="L",
                                        help="drop tracks seen in fewer than L tracked frames (default 5)")),
    ("--stride", "stride", dict(type=_positive_int, default=1, metavar="S",
                                help="track every S-th frame (default 1)")),
    ("--redetect-every", "redetect_every", dict(
        type=_positive_int, default=5, metavar="K",
        help="look for new corners every K frames where no track is (default 5)")),
    ("--fb-max", "fb_max", dict(type=_positive_float, default=1.0, metavar="PX",
                                help="largest forward-backward error of a step, pixels (default 1)")),
    ("--max-frames", "max_frames", dict(type=_int_at_least(2), default=None, metavar="N",
                                        help="stop after N tracked frames")),
)


def add_track_arguments(parser, rename: dict[str, str] | None = None) -> None:
    """Add the tracker's options (those of ``laav track``) to ``parser`` (or an argument group).

    ``rename`` maps a flag to another where the parser has one of that name already
    (``laav-explore`` has its own ``--max-points``). Read them back with :func:`track_options`.
    """
    rename = rename or {}
    for flag, key, kw in TRACK_OPTIONS:
        parser.add_argument(rename.get(flag, flag), dest=f"track_{key}", **kw)


def track_options(args) -> dict:
    """The keyword arguments of :func:`laav.track.track` that :func:`add_track_arguments`'s
    options hold in ``args``."""
    return {key: getattr(args, f"track_{key}") for _, key, _ in TRACK_OPTIONS}


def _add_track(sub) -> None:
    tr = sub.add_parser(
        "track", help="track features through a video and write tracks.npz",
        description="Track corners through a video (anything OpenCV opens) or a folder of "
                    "images with pyramidal Lucas-Kanade and a forward-backward check; write "
                    ".npz with points (F, P, 2, NaN where not visible), visible (F, P) and "
                    "name. Needs OpenCV (pip install 'laav[track]').")
    tr.add_argument("video", metavar="VIDEO", help="video file or folder of frames")
    tr.add_argument("--out", "-o", metavar="NPZ",
                    help="output file, or folder to write it in (an existing one, or a path ending "
                         "in /: created) (default: <video name>_tracks.npz in the current folder)")
    add_track_arguments(tr)
    tr.add_argument("--quiet", "-q", action="store_true", help="no progress bar")


def _cmd_track(args) -> int:
    from . import safe_name
    from .track import TrackError, save_tracks, track

    # FFmpeg's own log (e.g. "moov atom not found") would add lines to our one-line errors
    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
    _output_path(args.out, "tracks.npz")  # a bad --out said before the tracking, not after
    try:
        tracks = track(args.video, **track_options(args), progress=False if args.quiet else None)
    except TrackError as exc:
        raise _UsageError(str(exc)) from None
    out = _output_path(args.out, f"{safe_name(tracks.name)}_tracks.npz")
    try:
        save_tracks(tracks, out)
    except OSError as exc:
        raise _UsageError(f"{out}: cannot write tracks ({exc.strerror or exc})") from None
    vis = tracks.visible
    print(f"tracks: {out} ({tracks.n_tracks} tracks over {tracks.n_frames} frames, "
          f"{100 * vis.mean():.0f} % of entries visible, {len(tracks.complete())} visible in "
          "every frame)")
    return 0


def _names_a_folder(given: str) -> bool:
    """Whether the path ``given`` can only be a folder: it ends with a separator, or its last
    part is ``.`` or ``..`` (which :class:`pathlib.Path` would drop or keep as a name)."""
    last = given.replace(os.sep, "/").rsplit("/", 1)[-1]
    return last in ("", ".", "..")


def _output_path(given: str | None, default: str) -> Path:
    """Where a command writes its file: ``default`` (a base name) in the current folder when
    ``--out`` was not given; inside ``given`` when it is a folder or ends with a path
    separator (created, with its parents: folders only where the user said so); else
    ``given`` itself, its parent folders created. An empty ``--out``, or a parent that is a
    file, is a usage error (exit code 2)."""
    if given is None:
        return Path(default)
    if not given.strip():
        raise _UsageError("--out is empty: give a file or a folder")
    out = Path(given)
    folder = out if _names_a_folder(given) or out.is_dir() else out.parent
    for part in (folder, *folder.parents):
        if part.exists() and not part.is_dir():
            raise _UsageError(f"{given}: {part} is a file, not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _UsageError(f"{given}: cannot create the folder {folder} "
                          f"({exc.strerror or exc})") from None
    return folder / default if folder == out else out


def _input_name(seq) -> str:
    """The default output's base name: the input file's name (``Sequence.source``; without
    Hopkins155's ``_truth``), not the name stored in the file, which every track file of one
    video shares (``laav track`` stores the video's name), so that two runs do not overwrite
    one labels file; a safe base name either way (:func:`laav.safe_name`)."""
    from . import safe_name
    from .io import _name_from_path

    src = getattr(seq, "source", None)
    name = _name_from_path(Path(src)) if src and not str(src).startswith("<") else seq.name
    return safe_name(name)


def _cmd_segment(args) -> int:
    from . import (
        misclassification_rate,
        random_voting,
        segment,
    )
    from ._sequence import MIN_POINTS
    from .bench import params_and_seed
    from .io import point_numbers

    params, file_seed = params_and_seed(args.param, args.preset, args.params)
    if args.seed is None:  # the params file's, as laav-explore --params takes it, else 0
        args.seed = 0 if file_seed is None else file_seed
    seq, kept = _load_for_command(args)
    out = _output_path(args.out, f"{_input_name(seq)}_labels.csv")  # before the work
    C = args.motions if args.motions is not None else seq.n_motions
    if C is None:
        raise _UsageError(f"{args.file}: no ground-truth labels in the file; give the number "
                          "of motions with --motions C (or --motions auto)")
    if C != "auto" and int(C) > 1 and seq.n_points < MIN_POINTS * int(C):  # as laav-explore
        raise _UsageError(f"{args.file}: {seq.n_points} tracks, fewer than the "
                          f"{MIN_POINTS * int(C)} needed for {int(C)} motions (the 8-point "
                          f"algorithm fits each motion with at least {MIN_POINTS})")
    try:
        if C == "auto":
            from .motions import estimate_motions

            count = estimate_motions(seq, params=params, random_state=args.seed)
            C = count.n_motions
            print(f"motions: {C} (estimated: {count.explain()})")
        if args.method == "laav":
            labels = segment(seq, C, params, args.seed).labels
        else:
            labels = random_voting(seq, C, params, args.seed).labels
        other = None
        if args.check and args.method == "laav":
            # (its input checks are segment's, said once already)
            other = random_voting(seq, C, params, args.seed, check_input=False).labels
    except ValueError as exc:
        raise _UsageError(_named(args.file, exc)) from None
    # a name read from the file is only ever a base name in the current or given folder
    try:
        with open(out, "w", newline="") as fh:
            w = csv.writer(fh, lineterminator="\n")  # as the explorer's labels CSV
            w.writerow(("point", "label"))
            index = point_numbers(seq, kept).tolist()  # the file's numbers
            w.writerows((i, int(v)) for i, v in zip(index, labels))
    except OSError as exc:
        raise _UsageError(f"{out}: cannot write labels ({exc.strerror or exc})") from None
    print(f"labels: {out}")
    unlabelled = int((labels < 0).sum())
    if unlabelled:
        print(f"unlabelled: {unlabelled} of {len(labels)} points (label -1: seen too briefly to "
              "decide" + ("; they count as errors below)" if seq.labels is not None else ")"))
    if seq.labels is not None:
        err = 100.0 * misclassification_rate(seq.labels, labels)
        print(f"misclassification: {err:.2f} % ({seq.name}, {seq.n_points} points, "
              f"{C} motions, {args.method}, seed {args.seed})")
    if args.check and args.method == "rv":
        print("check: --method rv is plain Random Voting itself; nothing to compare with",
              file=sys.stderr)
    elif other is not None:
        _print_check(labels, other, seq.labels)
    return 0


def _print_check(labels, plain, truth) -> None:
    """``--check``'s lines: how far LAAV's labels and plain RV's are apart, and plain RV's
    error when there is a ground truth; above :data:`laav.metrics.DISAGREEMENT_WARN` a
    warning (stderr)."""
    from .metrics import DISAGREEMENT_WARN, labelling_distance, misclassification_rate

    d = labelling_distance(labels, plain)
    n = int(round(d * len(labels)))
    line = (f"check: LAAV and plain Random Voting label {n} of {len(labels)} points differently "
            f"({100 * d:.1f} %)")
    if truth is not None:
        line += f"; plain RV misclassification {100 * misclassification_rate(truth, plain):.2f} %"
    print(line)
    if d > DISAGREEMENT_WARN:
        print(f"laav segment: warning: LAAV and plain RV disagree on {100 * d:.1f} % of the points: "
              f"at least one of them is wrong on {50 * d:.1f} % or more; look at the result (e.g. "
              "laav-explore FILE) before using it", file=sys.stderr)


def _named(path, exc) -> str:
    """``exc``'s message, prefixed with ``path`` unless it already names the file first."""
    msg = str(exc)
    return msg if msg.startswith(f"{path}:") else f"{path}: {msg}"


def _split(values) -> list[str]:
    out = []
    for v in values:
        out += [s.strip() for s in v.split(",") if s.strip()]
    return out


def _check_out_folder(out: Path) -> None:
    """Refuse an output folder that cannot be created or written, before any work."""
    if out.exists() and not out.is_dir():
        raise _UsageError(f"{out}: output folder is a file")
    base = out
    while not base.exists() and base != base.parent:
        base = base.parent
    if not base.is_dir():
        raise _UsageError(f"{out}: cannot create the output folder ({base} is not a folder)")
    if not os.access(base, os.W_OK | os.X_OK):
        raise _UsageError(f"{out}: cannot write in {base} (permission denied)")


def _cmd_bench(args) -> int:
    from .bench import params_from_assignments, parse_missing, parse_noise, run_bench

    params = params_from_assignments(args.param, args.preset)
    noise = parse_noise(args.noise)
    missing = parse_missing(args.missing)
    methods = _split([args.methods])
    _check_out_folder(Path(args.out))

    summary = run_bench(
        data=args.data, out=args.out, methods=methods, seeds=args.seeds, noise=noise,
        only=_split(args.only) or None, jobs=args.jobs, scheduler=args.scheduler,
        params=params, progress=not args.quiet, report=not args.no_report,
        allow_mixed=args.allow_mixed, max_points=args.max_points, missing=missing,
    )
    err = sys.stderr
    if summary.interrupted:
        print(f"interrupted: {summary.completed} new runs kept in {summary.runs_csv}; "
              "rerun the same command to resume", file=err)
        return 130
    print(f"{summary.completed} runs done, {summary.already_done} already in "
          f"{summary.runs_csv}, {len(summary.failed)} failed", file=err)
    if summary.failed:
        print(f"failed runs are listed in {summary.out / 'failures.log'}; a rerun retries them",
              file=err)
    print(f"runs: {summary.runs_csv}")
    if summary.report is not None:
        print(f"report: {summary.report}")
        _print_table1(summary.report)
    return 1 if summary.failed else 0


def _print_table1(report: Path) -> None:
    lines = report.read_text().splitlines()
    try:
        start = next(i for i, ln in enumerate(lines) if ln.startswith("## Table 1"))
    except StopIteration:
        return
    block = []
    for ln in lines[start + 2:]:
        if not ln.startswith("|"):
            break
        block.append(ln)
    print("\n".join([lines[start][3:], *block]))


def _cmd_report(args) -> int:
    from .bench import RUNS_CSV
    from .report import write_report

    d = Path(args.dir)
    if not (d / RUNS_CSV).is_file():
        raise _UsageError(f"{d}: no {RUNS_CSV} here (run `laav bench --out {d}` first)")
    path = write_report(d)
    print(f"report: {path}")
    _print_table1(path)
    return 0


@contextlib.contextmanager
def warnings_as_lines(prog: str):
    """LAAV's warnings (:class:`laav.LaavWarning`) shown as one line each,
    ``PROG: warning: MESSAGE``, instead of Python's file, line number and source line
    (the format only: a caller recording warnings still records them)."""
    import warnings

    from ._sequence import LaavWarning

    plain = warnings.formatwarning

    def one_line(message, category, filename, lineno, line=None):
        if issubclass(category, LaavWarning):
            return f"{prog}: warning: {message}\n"
        return plain(message, category, filename, lineno, line)

    warnings.formatwarning = one_line
    try:
        yield
    finally:
        warnings.formatwarning = plain


def main(argv=None) -> int:
    """Entry point of the ``laav`` console script; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    from .bench import BenchError

    commands = {"segment": _cmd_segment, "bench": _cmd_bench, "report": _cmd_report,
                "convert": _cmd_convert, "track": _cmd_track}
    try:
        with warnings_as_lines(f"laav {args.command}"):
            return commands[args.command](args)
    except (_UsageError, BenchError) as exc:
        print(f"laav {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # a path the command could not read or write
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"laav {args.command}: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
