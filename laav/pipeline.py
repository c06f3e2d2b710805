"""The whole LAAV pipeline: :func:`segment` and the staged :class:`Pipeline`.

The scikit-learn estimator :class:`laav.LAAV` wrapping them is in :mod:`laav.estimator`.

Randomness: one integer ``seed`` is split by :class:`numpy.random.SeedSequence` into one
independent stream per random stage (atoms, fine-to-coarse, voting), and every run of a
stage starts a fresh generator from its stream. A stage's output therefore depends only
on its inputs, its parameters and the seed, which is what lets :class:`Pipeline` rerun
only the stages downstream of a change and still equal a fresh :func:`segment`.
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np

from ._interrupt import check as check_interrupt
from ._random import check_seed, resolve_seed
from ._sequence import Sequence, check_degenerate, warn_missing_motions
from ._threads import single_threaded
from .atoms import Atoms, MaskedNeighbourhoods, Neighbourhoods, build_atoms
from .coarse import Coarse, merge_models
from .graph import AtomGraph, atom_graph
from .multicut import Multicut, solve_multicut
from .params import STAGE_PARAMS, STAGES, LaavParams, as_params, stages_affected
from .voting import NOT_PLAIN_FIELDS, SELECTION_FIELDS, Voting, informed_preview, random_voting

#: Plain RV's runs are kept for this many (seed, C, ``rv_*`` settings), the most recent: a
#: step back to a seed shown before (or an interrupted seed change) reuses them.
PLAIN_MEMOS = 4

__all__ = ["LaavResult", "segment", "Pipeline", "preload"]


@dataclass(frozen=True, eq=False)
class LaavResult:
    """Everything LAAV computed for one sequence.

    Attributes
    ----------
    labels : ndarray of shape (P,), int64
        Final motion of every point; -1 for a point seen too briefly to decide (missing
        data only, see :attr:`unlabelled_code`).
    atoms, graph, multicut, coarse, voting
        The stage results, in pipeline order.
    timings : dict of str -> float
        Seconds spent in each stage of the run that produced this result (0 for a stage
        reused from an earlier run).
    params : LaavParams
    n_motions : int
    seed : int
    motion_count : MotionCount or None
        How C was estimated when :func:`segment` was asked for ``"auto"``.
    noise_sigma : float or None
        With ``params.noise_adaptive``: the tracks' pixel noise measured
        (:func:`laav.noise.estimate_noise`, px per coordinate); the stages ran with
        ``params.for_noise(noise_sigma)`` (:attr:`run_params`). None otherwise.
    """

    labels: np.ndarray
    atoms: Atoms
    graph: AtomGraph
    multicut: Multicut
    coarse: Coarse
    voting: Voting
    timings: dict = field(default_factory=dict)
    params: LaavParams = field(default_factory=LaavParams)
    n_motions: int = 2
    seed: int = 0
    motion_count: object = None
    noise_sigma: float | None = None

    @property
    def run_params(self) -> LaavParams:
        """The parameters the stages ran with: :attr:`params`, adapted to
        :attr:`noise_sigma` when ``params.noise_adaptive`` (:meth:`LaavParams.for_noise`)."""
        return self.params if self.noise_sigma is None else self.params.for_noise(self.noise_sigma)

    @property
    def unlabelled_code(self) -> np.ndarray:
        """(P,) int8: why each point has label -1, a key of
        :data:`laav.UNLABELLED_REASONS` (1: seen too briefly, no voting frame pair sees
        it), 0 for a labelled point. All 0 on complete data."""
        code = self.voting.unlabelled_code
        return np.zeros(self.labels.size, np.int8) if code is None else code

    @property
    def unlabelled_reason(self) -> dict:
        """``{point: sentence}`` for every point with label -1 (empty on complete data)."""
        from ._visibility import UNLABELLED_REASONS

        code = self.unlabelled_code
        return {int(q): UNLABELLED_REASONS[int(code[q])] for q in np.flatnonzero(code)}

    def stage_labels(self) -> dict:
        """Point labels after each stage (-1 where a stage leaves a point unlabelled).

        Keys: ``"fine"`` (fine model), ``"coarse"`` (motion from atoms), ``"final"``.
        """
        return {
            "fine": self.coarse.fine_point_labels,
            "coarse": self.coarse.point_labels,
            "final": self.labels,
        }


def _stage_rngs(seed: int):
    children = np.random.SeedSequence(seed).spawn(3)
    return {"atoms": children[0], "coarse": children[1], "voting": children[2]}


def _check_inputs(seq, n_motions, degenerate: bool = True):
    """The sequence as a :class:`Sequence` and C as an int, validated; with ``degenerate``
    also :func:`check_degenerate` (reads every coordinate: once per sequence and C)."""
    if not isinstance(seq, Sequence):
        seq = Sequence(np.asarray(seq, dtype=np.float64))
    if not isinstance(n_motions, (int, np.integer)) or isinstance(n_motions, bool):
        raise ValueError(f"n_motions must be an integer, got {n_motions!r}")
    if n_motions < 1:
        raise ValueError(f"n_motions must be >= 1, got {n_motions}")
    if n_motions > seq.n_points:
        raise ValueError(f"n_motions ({n_motions}) exceeds the number of points ({seq.n_points})")
    if degenerate:
        check_degenerate(seq, int(n_motions))
    return seq, int(n_motions)


def _check_frame_pairs(seq: Sequence, C: int, params: LaavParams) -> None:
    """Incomplete tracks: raise ValueError, naming the file, before any stage runs when no
    two frames share the points the fine-tuning's fits need (``max(8, rv_sample_size)``
    per motion; :func:`laav._visibility.pair_pool`)."""
    if seq.is_complete or C < 2:
        return
    from ._visibility import pair_pool

    try:
        pair_pool(seq.visible, max(8, params.rv_sample_size) * C)
    except ValueError as err:
        raise ValueError(f"{seq.source}: {err}") from None


class Pipeline:
    """LAAV staged for live recomputation.

    Parameters
    ----------
    seq : Sequence or ndarray of shape (F, P, 2)
        May have missing entries (``Sequence(..., visible=mask)``): every stage then runs
        its missing-data variant (``docs/ALGORITHM.md``, "Missing data").
    n_motions : int
        C.
    params : LaavParams, optional
    seed : int
    preview : callable, optional
        Given the result with LAAV's own fine-tuning alone before plain Random Voting, or
        the missing-motion starts of LAAV's own chain, run (as :meth:`update`'s
        ``preview``).
    helper : laav.helper.VotingHelper, optional
        Speed only: LAAV's own voting trials run half in the helper's process (the machine's
        second core); the labels are those without it. May be set or changed later
        (the ``helper`` attribute).
    full_shortlist : bool
        The joint merge scores every partition of its shortlist (``coarse.shortlist``), not
        only those that could still win: the same labels, the whole comparison (what the
        explorer's card 3 draws), at some of the coarse stage's time. :meth:`update` can
        change it (the coarse stage then reruns).

    Attributes
    ----------
    result : LaavResult
        The latest result.

    Notes
    -----
    The fine-tuning (Random Voting) is the costliest stage on most sequences. When a
    rerun leaves its inputs as they were (the coarse labels, the atoms, the ``rv_*``
    settings, C and the seed), for instance a λ change that does not alter the merge,
    its previous result is reused (its timing is then only that of the check). The
    result is identical to a recomputation: the stage's generator depends only on the seed.
    The coarse stage keeps what does not depend on λ for the present multicut (its pairwise
    samples and their fits, the coding statistics and shortlist, the joint merge's robust
    fits: ``merge_models(memo=...)``), so a λ move reruns little (without ``full_shortlist``
    it may score partitions the first run did not, whose motions are then fitted).
    With plain Random Voting beside LAAV's trial (:meth:`LaavParams.with_plain_rv`, and on
    incomplete tracks) a rerun of the fine-tuning reruns LAAV's informed trial only: plain
    RV's runs (and their polished candidates) do not depend on the coarse labels and are
    kept for the last :data:`PLAIN_MEMOS` values of the seed, C and the ``rv_*`` settings
    (``plain_memo`` of :func:`laav.random_voting`; labels identical), so a step back to a
    seed shown before reruns only LAAV's own stages.

    Examples
    --------
    >>> pipe = Pipeline(seq, 2)                     # doctest: +SKIP
    >>> res = pipe.update(lam=5.0)                  # reuses atoms, graph and multicut
    """

    def __init__(self, seq, n_motions: int, params: LaavParams | None = None, seed: int = 0, *,
                 preview=None, helper=None, full_shortlist: bool = False):
        self.params = as_params(params)
        self.seq, self.n_motions = _check_inputs(seq, n_motions)
        self.params.n_fine(self.n_motions, self.seq.is_complete)
        _check_frame_pairs(self.seq, self.n_motions, self.params)
        self.seed = check_seed(seed)
        #: speed only (:class:`laav.helper.VotingHelper`): LAAV's own trials half in its process
        self.helper = helper
        #: speed only, with a helper: the paper's pairwise votes of the coarse stage (which
        #: the default merge leaves unfitted; ``Coarse.vote_samples``, what a viewer draws)
        #: are fitted in the helper while the voting runs (the explorer sets it)
        self.prefetch_votes = False
        #: the joint merge scores every partition of its shortlist, not only those that could
        #: still win (:func:`laav.coarse.merge_models`' ``full_shortlist``; the same labels):
        #: for a viewer of the comparison (the explorer's card 3)
        self.full_shortlist = bool(full_shortlist)
        self._lock = threading.Lock()
        self._distances = None
        self._noise: float | None = None  # the tracks' measured noise (noise_adaptive), px
        self._stages: dict = {}
        self._voting_memo: tuple | None = None
        #: what the coarse stage keeps across λ moves for the present multicut
        #: (:func:`laav.coarse.merge_models`' ``memo``); emptied when the multicut reruns
        self._coarse_memo: dict = {}
        #: (seed, C, rv_* settings) -> plain RV's runs, the last :data:`PLAIN_MEMOS` kept
        self._plain_memos: OrderedDict = OrderedDict()
        self.result = self._run("atoms", preview)

    def _voting_key(self, init) -> tuple:
        """Everything the fine-tuning's result depends on (its generator comes from the seed)."""
        rv = tuple((k, v) for k, v in self._run_params().to_dict().items()
                   if k in STAGE_PARAMS["voting"] or k in SELECTION_FIELDS)
        return (self.seed, self.n_motions, rv, init)

    def _same_voting_inputs(self, key: tuple) -> bool:
        old = self._voting_memo[0]
        if old[:3] != key[:3]:
            return False
        return all((a is None and b is None) or (a is not None and b is not None and np.array_equal(a, b))
                   for a, b in zip(old[3:], key[3:]))

    def _run_params(self) -> LaavParams:
        """``params``, or with ``noise_adaptive`` its :meth:`LaavParams.for_noise` for the
        tracks' noise, measured once per sequence (it depends on the coordinates alone)."""
        if not self.params.noise_adaptive:
            return self.params
        if self._noise is None:
            from .noise import estimate_noise

            self._noise = estimate_noise(self.seq.points,
                                         None if self.seq.is_complete else self.seq.visible)
        return self.params.for_noise(self._noise)

    def _rng(self, stage: str) -> np.random.Generator:
        return np.random.default_rng(_stage_rngs(self.seed)[stage])

    @single_threaded  # one BLAS/OpenMP thread while the stages run (laav/_threads.py)
    def _run(self, start: str, preview=None) -> LaavResult:
        seq, C = self.seq, self.n_motions
        timings = dict.fromkeys(STAGES, 0.0)
        t = time.perf_counter()
        measure = self.params.noise_adaptive and self._noise is None  # once per sequence
        p = self._run_params()  # noise_adaptive: the thresholds for the measured noise
        if measure:
            timings["atoms"] += time.perf_counter() - t
        todo = STAGES[STAGES.index(start):]
        st = self._stages
        if self._distances is None:  # kept for every later run: R1/R2 changes reuse it
            t = time.perf_counter()
            self._distances = (Neighbourhoods(seq.points) if seq.is_complete
                               else MaskedNeighbourhoods(seq.points, seq.visible))
            timings["atoms"] += time.perf_counter() - t
        for stage in todo:
            check_interrupt()  # a caller's stop request (laav._interrupt), between stages
            t = time.perf_counter()
            if stage == "atoms":
                st["atoms"] = build_atoms(seq, p, self._rng("atoms"), self._distances)
            elif stage == "graph":
                st["graph"] = atom_graph(seq, st["atoms"], p, self._distances)
            elif stage == "multicut":
                st["multicut"] = solve_multicut(st["graph"], p.n_fine(C, seq.is_complete))
                self._coarse_memo = {}
            elif stage == "coarse":
                st["coarse"] = merge_models(seq, st["atoms"], st["multicut"], C, p,
                                            self._rng("coarse"), memo=self._coarse_memo,
                                            full_shortlist=self.full_shortlist)
            elif stage == "voting":
                init = st["coarse"].point_labels
                if C == 1 or not (init >= 0).any():
                    init = None  # no atom formed: plain Random Voting
                key = self._voting_key(init)
                if self._voting_memo is not None and self._same_voting_inputs(key):
                    st["voting"] = self._voting_memo[1]  # same inputs, same result
                    continue  # reused: its time stays 0 (as for the stages not rerun)
                else:
                    # plain RV's runs: kept for the last PLAIN_MEMOS (seed, C, rv_*) (its
                    # polished candidates' costs are keyed on the selection's fields inside)
                    pkey = (key[0], key[1], tuple(kv for kv in key[2] if kv[0] not in
                                                  SELECTION_FIELDS + NOT_PLAIN_FIELDS))
                    memo = self._plain_memos.get(pkey)
                    if memo is None:  # new seed, C or rv_* settings
                        memo = self._plain_memos[pkey] = {}
                        while len(self._plain_memos) > PLAIN_MEMOS:
                            self._plain_memos.popitem(last=False)
                    self._plain_memos.move_to_end(pkey)
                    if (preview is not None and ("run", 1) not in memo and init is not None
                            and seq.is_complete):  # plain RV will run: LAAV's own trial first
                        t += self._preview(preview, p, init, memo, timings, t)
                    votes = self._fit_votes_elsewhere(st["coarse"])
                    own = self._own_preview(preview, timings, t, p, init)
                    try:  # no atom: plain RV, whose input checks segment() made already
                        st["voting"] = random_voting(seq, C, p, self._rng("voting"), init_labels=init,
                                                     plain_memo=memo,
                                                     check_input=False, helper=self.helper,
                                                     preview=own)
                    except BaseException:
                        if votes is not None:
                            self.helper.stop(votes[1])
                        raise
                    self._voting_memo = (key, st["voting"])
                    if own is not None:
                        t += own.spent  # (the preview's own time is not the stage's)
                    waited = time.perf_counter()
                    self._take_votes(votes)
                    waited = time.perf_counter() - waited
                    timings["coarse"] += waited  # (the coarse stage's votes, not the voting)
                    t += waited
            timings[stage] += time.perf_counter() - t
        return self._result(st["voting"], timings)

    def _fit_votes_elsewhere(self, coarse) -> tuple | None:
        """With :attr:`prefetch_votes` and a helper: ``coarse``'s unfitted pairwise votes
        sent to the helper's process, (fits, handle); else None."""
        if not self.prefetch_votes or self.helper is None or coarse is None:
            return None
        fits = coarse.pairwise.unfitted()
        args = None if fits is None else fits.pending()
        if args is None:
            return None
        from .coarse import fit_pairwise

        handle = self.helper.submit_call(fit_pairwise, *args)
        return None if handle is None else (fits, handle)

    def _take_votes(self, votes: tuple | None) -> None:
        """The fits of :meth:`_fit_votes_elsewhere` into the coarse stage's votes (when the
        helper delivered them; else they are fitted here when first read)."""
        if votes is None:
            return
        fits, handle = votes
        out = self.helper.result(handle, check_interrupt)
        if out is not None:
            fits.put(out)

    def _result(self, voting: Voting, timings: dict) -> LaavResult:
        st = self._stages
        return LaavResult(
            labels=voting.labels, atoms=st["atoms"], graph=st["graph"],
            multicut=st["multicut"], coarse=st["coarse"], voting=voting,
            timings=timings, params=self.params, n_motions=self.n_motions, seed=self.seed,
            noise_sigma=self._noise if self.params.noise_adaptive else None,
        )

    def _preview(self, preview, p: LaavParams, init: np.ndarray, memo: dict, timings: dict,
                 t: float) -> float:
        """Hand ``preview`` the result with LAAV's own fine-tuning alone (see :meth:`update`),
        its voting time counted from ``t`` (the stage's start); the seconds ``preview`` itself
        took (not the stage's)."""
        voting = informed_preview(self.seq.points, self.n_motions, p, self._rng("voting"), init,
                                  plain_memo=memo)
        return 0.0 if voting is None else self._hand_over(preview, voting, timings, t)

    def _hand_over(self, preview, voting: Voting, timings: dict, t: float) -> float:
        """``preview`` given the result with ``voting``, its voting time counted from ``t``
        (the stage's start); the seconds ``preview`` itself took (not the stage's)."""
        now = dict(timings)
        now["voting"] += time.perf_counter() - t
        t_call = time.perf_counter()
        preview(self._result(voting, now))
        return time.perf_counter() - t_call

    def _own_preview(self, preview, timings: dict, t: float, p: LaavParams, init):
        """``preview`` as :func:`random_voting`'s hook for LAAV's own chain (``rv_select=
        "laav"``, complete tracks): called with the informed trial's result alone when the
        missing-motion gate lets some start through, it hands ``preview`` that result, its
        voting time counted from ``t``; the seconds ``preview`` took are added up in its
        ``spent``. None when there is no ``preview`` or another chain runs."""
        if preview is None or p.rv_select != "laav" or init is None or not self.seq.is_complete:
            return None

        def hook(voting: Voting) -> None:
            hook.spent += self._hand_over(preview, voting, timings, t)

        hook.spent = 0.0
        return hook

    def update(self, *, preview=None, **changed) -> LaavResult:
        """Change parameters (any :class:`LaavParams` field, ``seed``, ``n_motions`` or
        ``full_shortlist``) and recompute only the stages downstream of the change.

        ``preview``: a callable that, when the fine-tuning must run plain Random Voting
        afresh (a new seed, C or ``rv_*`` setting; complete tracks of at most
        ``rv_max_points`` points, ``rv_select`` ``"joint"`` or ``"subspace"``), is first
        given the result with LAAV's own
        fine-tuning alone (:func:`laav.voting.informed_preview`: the informed trial,
        refined and reassigned, ``voting.selected == "informed"``, no costs), in this thread,
        before plain RV and the selection run (for a live view: most of a seed change's
        time is theirs). The trial is not run again after it, the returned result is the
        same with or without ``preview``, and the time ``preview`` takes is not in the
        result's ``timings``. With LAAV's own chain (``rv_select="laav"``, the default;
        complete tracks) it is given the result with the informed trial alone (polished,
        selected and descended; ``voting.skipped_starts`` names the missing-motion starts not
        run) whenever the gate (``rv_missing_gate``) lets some start through, before their
        trials run; the same holds.

        Returns
        -------
        LaavResult
            Equal to a fresh :func:`segment` with the same inputs.

        Raises
        ------
        ValueError
            For invalid values; the pipeline then keeps its previous state and result.
        """
        with self._lock:
            full = bool(changed.pop("full_shortlist", self.full_shortlist))
            seed = check_seed(changed.pop("seed", self.seed))
            C = changed.pop("n_motions", self.n_motions)
            new_params = self.params.replace(**changed) if changed else self.params
            # the sequence is the one checked at construction: only a new C is checked again
            _, C = _check_inputs(self.seq, C, degenerate=C != self.n_motions)
            complete = self.seq.is_complete
            n_fine = new_params.n_fine(C, complete)
            if C != self.n_motions or new_params.rv_sample_size != self.params.rv_sample_size:
                _check_frame_pairs(self.seq, C, new_params)
            diff = {k for k, v in new_params.to_dict().items() if v != getattr(self.params, k)}
            starts = [stages_affected(diff)] if diff else []
            # a coarse-stage field can set the multicut's model count (coarse_merge: 2C/3C/4C)
            if C != self.n_motions or n_fine != self.params.n_fine(C, complete):
                starts.append("multicut")
            if seed != self.seed:
                starts.append("atoms")
            if full != self.full_shortlist:  # (the same labels: the comparison shown)
                starts.append("coarse")
            starts = [s for s in starts if s is not None]
            start = min(starts, key=STAGES.index) if starts else None
            old = (self.params, self.n_motions, self.seed, dict(self._stages), self._coarse_memo,
                   self.full_shortlist)
            self.params, self.n_motions, self.seed, self.full_shortlist = new_params, C, seed, full
            if start is None:
                return self.result
            try:
                self.result = self._run(start, preview)
            except BaseException:
                # roll everything back, cached stage results included (also on Ctrl-C: a
                # KeyboardInterrupt is no Exception, and the next update must not find the
                # new settings beside the old result)
                (self.params, self.n_motions, self.seed, self._stages,
                 self._coarse_memo, self.full_shortlist) = old  # the memo of the multicut kept
                raise
            return self.result


def preload() -> None:
    """Import the modules the pipeline loads on first use.

    ``import laav`` stays light (about 0.07 s) because scipy's graph, distance and
    assignment routines are imported where they are first needed. An application that
    starts a user interface can call this in a background thread meanwhile. (The pipeline
    does not use scikit-learn: its spectral clustering is :mod:`laav._spectral`'s; only
    the estimators :class:`laav.LAAV` and :class:`laav.RandomVoting` import it.)
    """
    import scipy.linalg  # noqa: F401
    import scipy.optimize  # noqa: F401
    import scipy.sparse.csgraph  # noqa: F401
    import scipy.sparse.linalg  # noqa: F401
    import scipy.spatial.distance  # noqa: F401

    from . import _spectral  # noqa: F401  (imported by the stages where first needed)


def segment(seq, n_motions: int | str, params: LaavParams | None = None, seed: int = 0, *,
            random_state=None) -> LaavResult:
    """Segment trajectories into ``n_motions`` motions with LAAV.

    Parameters
    ----------
    seq : Sequence or ndarray of shape (F, P, 2)
    n_motions : int or "auto"
        C, the number of motions; ``"auto"`` estimates it first
        (:func:`laav.motions.estimate_motions`, same seed, up to 5 motions; the estimate
        is kept as ``result.motion_count``).
    params : LaavParams, optional
    seed : int
        Same seed, same labels.
    random_state : None, int, numpy.random.Generator or RandomState, optional
        scikit-learn style alternative to ``seed``, used instead of it when given: an int
        is the seed itself, a generator gives one draw. None (default): ``seed`` is used.

    Returns
    -------
    LaavResult

    Notes
    -----
    A sequence with missing entries (``not seq.is_complete``) is segmented by every
    stage's missing-data variant (``docs/ALGORITHM.md``, "Missing data"); a point seen too
    briefly to decide gets label -1, with the reason in ``result.unlabelled_reason``.
    ``"auto"`` estimates C on the tracks seen in every frame (the estimate fits whole
    trajectories; :func:`laav.estimate_motions`), and raises ValueError when fewer than 16
    are.
    """
    seed = resolve_seed(seed, random_state)
    count = result = None
    if isinstance(n_motions, str):
        if n_motions != "auto":
            raise ValueError(f"n_motions must be an integer or 'auto', got {n_motions!r}")
        from .motions import _estimate_motions

        seed = check_seed(seed)
        count, result = _estimate_motions(seq, 5, seed, params)
        n_motions = count.n_motions
    if result is None:  # C given, or the estimate did not segment the whole sequence with it
        result = Pipeline(seq, n_motions, params, seed).result
    if count is not None:
        from dataclasses import replace

        result = replace(result, motion_count=count)
    warn_missing_motions(seq, result.labels, result.n_motions)  # names segment's caller
    _warn_no_atoms(seq, result)
    return result


def _warn_no_atoms(seq, result: LaavResult) -> None:
    """Warn (:class:`LaavWarning`) when no atom formed at C > 1: the fine-tuning then started
    from random labels, which is plain Random Voting, not LAAV (the explorer says the same)."""
    if result.n_motions > 1 and result.atoms.n_atoms == 0:
        import warnings

        from ._sequence import LaavWarning, user_stacklevel

        p = result.params
        warnings.warn(f"{getattr(seq, 'source', '<array>')}: no atom formed with R1 = {p.r1:g}, "
                      f"R2 = {p.r2:g} px: the fine-tuning started from random labels (plain Random "
                      "Voting, not LAAV); larger radii or a larger affine_threshold let atoms form",
                      LaavWarning, stacklevel=user_stacklevel())

