"""LAAV's own chain (issue 12): subspace votes in its informed trials, missing-motion
starts, and the choice among its trials by the joint merge's score (laav.own_chain,
laav.voting)."""

from __future__ import annotations

import numpy as np
import pytest

from laav import LaavParams, Sequence, misclassification_rate, random_voting, segment
from laav.own_chain import outlier_points, veto
from laav.subspace_votes import SubspaceVotes
from laav.voting import joint_score, missing_motion_start

synthetic = pytest.importorskip("laav.synthetic")


def two_motions(seed=0):
    return synthetic.make_sequence(n_objects=1, n_frames=20, n_points=300, rng=seed)


def test_plain_rv_never_uses_subspace_votes():
    """Plain RV's random starts vote as the RV paper says, whatever the weight."""
    seq = two_motions(1)
    on = random_voting(seq, 2, LaavParams(rv_subspace_weight=1.0, rv_max_iter=40), seed=3)
    off = random_voting(seq, 2, LaavParams(rv_subspace_weight=0.0, rv_max_iter=40), seed=3)
    assert np.array_equal(on.labels, off.labels) and on.n_iterations == off.n_iterations


def test_subspace_votes_change_the_informed_trial():
    seq = two_motions(2)
    start = np.where(np.random.default_rng(0).random(seq.n_points) < 0.7, seq.labels, -1)
    p = LaavParams(rv_select="none", rv_refine=False, rv_reassign=False, rv_subspace_weight=1.0)
    on = random_voting(seq, 2, p, seed=0, init_labels=start)
    off = random_voting(seq, 2, p.replace(rv_subspace_weight=0.0), seed=0, init_labels=start)
    assert on.trial_iterations != off.trial_iterations or not np.array_equal(on.votes, off.votes)


def test_the_informed_trial_reports_the_votes_it_used():
    """``Voting.informed_subspace_weight`` says how LAAV's trial voted: the default's
    weight with a start labelling most points, none from a sparse start, with the paper
    preset or on missing data; None for plain RV. The explorer names it as ours."""
    from explorer.views import rv_summary
    from laav.voting import SUBSPACE_VOTES_MIN_START

    seq = two_motions(2)
    rng = np.random.default_rng(0)
    dense = np.where(rng.random(seq.n_points) < 0.7, seq.labels, -1)
    sparse = np.where(rng.random(seq.n_points) < SUBSPACE_VOTES_MIN_START / 2, seq.labels, -1)
    p = LaavParams(rv_max_iter=40)
    on = random_voting(seq, 2, p, seed=0, init_labels=dense)
    assert on.informed_subspace_weight == p.rv_subspace_weight == 1.0
    assert random_voting(seq, 2, p, seed=0, init_labels=sparse).informed_subspace_weight == 0.0
    paper = random_voting(seq, 2, LaavParams.paper(rv_max_iter=40), seed=0, init_labels=dense)
    assert paper.informed_subspace_weight == 0.0
    vis = np.ones((seq.n_frames, seq.n_points), dtype=bool)
    vis[:3, :20] = False
    holes = Sequence(seq.points, seq.labels, visible=vis)
    assert random_voting(holes, 2, p, seed=0, init_labels=dense).informed_subspace_weight == 0.0
    plain = random_voting(seq, 2, p, seed=0)
    assert plain.informed_subspace_weight is None
    text = rv_summary(on, plain)
    assert "1 × squared distance" in text and "ours" in text
    assert "Sampson distance alone (the RV paper's)" in rv_summary(paper, plain)


def test_subspace_distances_tell_the_motions_apart():
    """Each motion's points lie near the rank-4 subspace fitted to 16 of them, the other
    motion's far from it (noise-free synthetic scenes)."""
    seq = synthetic.make_sequence(n_objects=1, n_frames=20, n_points=300, noise=0.0, rng=4)
    sv = SubspaceVotes(seq.points, 1.0, 16)
    idx = np.stack([np.flatnonzero(seq.labels == g)[:16] for g in (0, 1)])  # (C, m)
    d = sv.distances(idx)  # (C, P)
    for g in (0, 1):
        own, other = d[g, seq.labels == g], d[g, seq.labels != g]
        # the scenes have some perspective: own distances small, not zero
        assert np.median(own) < 0.1 * np.median(other) and np.median(other) > 1.0


def test_subspace_votes_fit_an_orthonormal_basis_of_the_sample_also_when_rank_deficient():
    """The subspace votes' basis is orthonormal and spans the sample's leading 4 singular
    directions (the distances then equal a direct SVD's), also for a sample spanning only 2
    dimensions (two trajectories repeated: there it comes from QR, dividing by near-zero
    singular values would not give unit vectors)."""
    seq = synthetic.make_sequence(n_objects=1, n_frames=12, n_points=120, noise=0.5, rng=2)
    sv = SubspaceVotes(seq.points, 1.0, 16)
    F, W = seq.points.shape[0], sv.W
    flat = np.r_[np.zeros(8, dtype=np.int64), np.ones(8, dtype=np.int64)]
    X = np.moveaxis(W[:, np.stack([np.arange(16), flat])], 0, -2)  # (2, 2F, 16)
    # the full-rank sample alone (divided by its singular values), with the flat one and the
    # flat one alone (both by QR: one sample spanning fewer than 4 dimensions is enough)
    lam = np.linalg.eigvalsh(np.swapaxes(X, -1, -2) @ X)[:, -4:]
    assert lam[0, 0] > 1e-8 * lam[0, -1] and lam[1, 0] < 1e-8 * lam[1, -1]
    for U in (sv.basis(X[:1]), sv.basis(X), sv.basis(X[1:])):
        assert np.allclose(np.swapaxes(U, -1, -2) @ U, np.eye(4), atol=1e-9)
    full = np.linalg.svd(W[:, :16], full_matrices=False)[0][:, :4]
    U = sv.basis(X)[0]
    assert np.allclose(U @ U.T, full @ full.T, atol=1e-9)
    got = sv.distances(np.arange(16)[None])[0]
    expect = ((W - full @ (full.T @ W)) ** 2).sum(axis=0) / F
    assert np.allclose(got, expect, rtol=1e-9, atol=1e-9 * np.abs(W).max() ** 2)


def small_motion_uncovered(seed):
    """A scene whose small motion (30 points) has no atom, and coarse labels that split the
    large motion in two by position (what stage 4 must do then), as on Hopkins155's
    `head` and `kanatani3`."""
    full = synthetic.make_sequence(n_objects=1, n_frames=20, n_points=400, rng=seed)
    big = int(np.bincount(full.labels).argmax())
    keep = np.r_[np.flatnonzero(full.labels == big), np.flatnonzero(full.labels != big)[:30]]
    seq = Sequence(full.points[:, keep], full.labels[keep], name="small uncovered")
    x = seq.points[0, :, 0]
    init = np.where(seq.labels == big, (x > np.median(x[seq.labels == big])).astype(np.int64), -1)
    return seq, init, big


@pytest.mark.parametrize("seed", [0, 1, 3])
def test_missing_motion_start_finds_the_motion_without_atoms(seed):
    """Merging the split pair and taking the unexplained uncovered points as motion C
    gives the truth's start, and the fine-tuning keeps that trial (the gate off); the paper's
    fine-tuning from the same coarse labels cannot find the small motion. With the gate
    (the default), the start's trials run only where LAAV's informed trial (its subspace
    votes) did not find the motion itself."""
    seq, init, big = small_motion_uncovered(seed)
    p = LaavParams.own_chain(rv_missing_gate=0.0)
    start = missing_motion_start(seq.points, init, 2, 0, 1, p, 8)
    assert start is not None
    new = start == 1
    assert new.sum() == 30 and (seq.labels[new] != big).all()
    res = random_voting(seq, 2, p, seed=0, init_labels=init)
    # the start's own trial kept (its second trial, rv_missing_trials, ends there too)
    assert res.selected == "missing motion (0+1)"
    assert set(res.costs) == {"informed", res.selected, res.selected + ", trial 2"}
    assert res.costs[res.selected] < res.costs["informed"]
    assert res.vetoed == ()  # the missing motion is one both labellings explain: no veto
    assert misclassification_rate(seq.labels, res.labels) < 0.01
    paper = random_voting(seq, 2, LaavParams.paper(), seed=0, init_labels=init)
    assert misclassification_rate(seq.labels, paper.labels) > 0.3
    gated = random_voting(seq, 2, LaavParams(), seed=0, init_labels=init)
    assert misclassification_rate(seq.labels, gated.labels) < 0.01
    if gated.skipped_starts:  # the informed trial found the small motion: nothing to look for
        assert gated.skipped_starts == ("missing motion (0+1)",) and gated.selected == "informed"
    else:
        assert gated.selected == res.selected and np.array_equal(gated.labels, res.labels)


def test_no_missing_motion_start_when_the_uncovered_points_are_like_the_covered_ones():
    """Every motion has atoms and a seventh of each motion's points is uncovered: the
    uncovered points fit the merged pair no worse than its covered points (the threshold
    is their 95th percentile), so fewer than 8 qualify and there is no start."""
    seq = two_motions(0)
    init = seq.labels.copy()
    init[::7] = -1
    assert missing_motion_start(seq.points, init, 2, 0, 1, LaavParams(), 8) is None


def test_joint_score_prefers_the_truth_and_needs_eight_points_a_motion():
    seq = two_motions(3)
    p = LaavParams()
    wrong = np.where(np.arange(seq.n_points) % 2 == 0, seq.labels, 1 - seq.labels)
    assert joint_score(seq.points, seq.labels, 2, p) < joint_score(seq.points, wrong, 2, p)
    tiny = np.zeros(seq.n_points, dtype=np.int64)
    tiny[:5] = 1
    assert joint_score(seq.points, tiny, 2, p) == float("inf")


def test_own_chain_is_the_default_and_the_presets():
    """The default is LAAV's own chain since 2026-12-02 (the joint merge on 4C fine models,
    subspace votes at the cross-validated weight 1, LAAV's own candidates, no plain RV);
    ``own_chain()`` is kept as the default; ``with_plain_rv()`` is the previous default
    (the epipolar merge on 2C, weight 0.3, plain RV and the joint selection); the paper's
    informed trial has no subspace votes."""
    own, default, plain = LaavParams.own_chain(), LaavParams(), LaavParams.with_plain_rv()
    assert own == default
    assert (default.coarse_merge, default.rv_select, default.rv_subspace_weight) == ("auto", "laav", 1.0)
    assert (plain.coarse_merge, plain.rv_select, plain.rv_subspace_weight) == ("epipolar", "joint", 0.3)
    assert LaavParams.with_plain_rv(lam=3.0).lam == 3.0
    assert LaavParams.paper().rv_subspace_weight == 0.0
    assert default.n_fine(2) == 8 and default.n_fine(2, complete=False) == 4 and plain.n_fine(2) == 4


def test_the_default_informed_trial_converges_faster_than_plain_rv():
    """The paper's claim (its Fig. 3), as the explorer's Random Voting card shows it: from
    the coarse labels, LAAV's informed trial converges, in fewer iterations than plain RV
    from random starts needs in all. Six seeded three-motion scenes; with the RV paper's
    votes alone (weight 0) the trial ran to its cap on scene 0 and took 132 on scene 4."""
    from laav import segment

    for s in range(6):
        seq = synthetic.make_sequence(n_objects=2, n_frames=20, n_points=300, rng=s)
        res = segment(seq, 3, seed=0)
        plain = random_voting(seq, 3, seed=0)
        v = res.voting
        assert v.informed_converged, s
        assert len(v.informed_changed) < plain.n_iterations, (s, len(v.informed_changed))
        assert misclassification_rate(seq.labels, res.labels) == 0.0, s


def test_the_paper_rv_module_takes_the_subspace_votes_only_as_an_extra_term():
    """``laav.rv`` is the RV paper's algorithm: it never reads ``rv_subspace_weight``; the
    subspace votes (ours) come in as ``extra``, for an informed trial alone on complete
    data, from ``laav.subspace_votes.for_informed_trial``."""
    from laav.rv import run_trials
    from laav.subspace_votes import SUBSPACE_VOTES_MIN_START, for_informed_trial

    seq = two_motions(2)
    P = seq.n_points
    p = LaavParams(rv_max_iter=20)
    known = np.ones(P, dtype=bool)
    extra = for_informed_trial(seq.points, p, known)
    assert isinstance(extra, SubspaceVotes) and extra.weight == 1.0
    assert for_informed_trial(seq.points, p.replace(rv_subspace_weight=0.0), known) is None
    assert for_informed_trial(seq.points, p, np.arange(P) < SUBSPACE_VOTES_MIN_START * P - 1) is None
    start = (seq.labels.copy(), np.eye(2)[seq.labels] * 5.0)
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="informed trial alone"):
        run_trials(seq.points, 2, p, rng, start, n_plain=2, extra=extra)
    # the weight in the parameters alone changes nothing in laav.rv
    a = run_trials(seq.points, 2, p, np.random.default_rng(1), start, n_plain=0)[0]
    b = run_trials(seq.points, 2, p.replace(rv_subspace_weight=3.0), np.random.default_rng(1),
                   start, n_plain=0)[0]
    c = run_trials(seq.points, 2, p, np.random.default_rng(1), start, n_plain=0, extra=extra)[0]
    assert np.array_equal(a[1], b[1]) and not np.array_equal(a[1], c[1])


def test_own_candidates_side_by_side_are_their_one_after_another_results(monkeypatch):
    """LAAV's informed and missing-motion trials run all side by side (speed only): every
    candidate's labels, iterations and score are those of one trial at a time, whatever
    ``rv_batch``; trials that end on the same labels share one polish (counted)."""
    import laav.own_chain as V
    import laav.rv as rv
    import laav.selection as S
    from explorer.demo import demo_sequence
    from laav import segment

    seq = demo_sequence()  # seed 1: seven trials (the informed one, two per missing-motion
    # start), one ending on the informed trial's very labels
    made, batches = [], []
    real, real_side, real_step = S.Polished, V.informed_side_by_side, rv._step

    class Counted(real):
        def __init__(self, *a, **k):
            made.append(1)
            super().__init__(*a, **k)

    def one_at_a_time(points, params, starts, extra, uses):  # the reference
        return [real_side(points, params, [s], extra, [u])[0] for s, u in zip(starts, uses)]

    monkeypatch.setattr(S, "Polished", Counted)
    monkeypatch.setattr(rv, "_step", lambda p, trials, *a: batches.append(len(trials)) or
                        real_step(p, trials, *a))
    runs = {}
    for b in (1, 2, 4):
        del made[:], batches[:]
        r = segment(seq, 3, LaavParams(rv_batch=b, rv_missing_gate=0.0), seed=1)
        runs[b] = (r, len(made))
        assert max(batches) == 7  # all seven side by side, whatever rv_batch
    monkeypatch.setattr(V, "informed_side_by_side", one_at_a_time)
    del made[:], batches[:]
    r = segment(seq, 3, LaavParams(rv_missing_gate=0.0), seed=1)
    runs[1] = (r, len(made))
    assert max(batches) == 1
    one, n_pol = runs[1]
    n_trials = 1 + 3 * LaavParams().rv_missing_trials  # 1 + C(C-1)/2 x rv_missing_trials
    assert len(one.voting.costs) == n_trials == 7 and len(one.voting.trial_iterations) == n_trials
    assert len(set(one.voting.costs.values())) <= n_pol < n_trials  # trials shared their polish
    for b in (2, 4):
        r, n = runs[b]
        np.testing.assert_array_equal(r.labels, one.labels)
        assert r.voting.costs == one.voting.costs and n == n_pol
        assert list(r.voting.trial_iterations) == list(one.voting.trial_iterations)
        np.testing.assert_array_equal(r.voting.informed_changed, one.voting.informed_changed)


def test_second_missing_motion_trials_leave_the_first_ones_as_they_were():
    """``rv_missing_trials``: each missing-motion start's first trial runs on the start's
    own stream whatever the count (the others on streams spawned from it, which draws
    nothing), so with two trials every candidate of one trial is there, with the same
    iterations and score, and every start has one more, on its own random draws."""
    from explorer.demo import demo_sequence
    from laav import segment

    seq = demo_sequence()
    one = segment(seq, 3, LaavParams(rv_missing_trials=1, rv_missing_gate=0.0), seed=1).voting
    two = segment(seq, 3, LaavParams(rv_missing_trials=2, rv_missing_gate=0.0), seed=1).voting
    assert len(one.costs) == 4 and len(two.costs) == 7
    # as before the second trials existed (c94e670, the same seed): each start's first trial
    # still runs on the start's own stream, not on one spawned from it
    assert one.trial_iterations == (106, 150, 50, 62)
    assert one.costs["missing motion (0+1)"] == pytest.approx(11542.75622046746, rel=1e-9)
    for name, cost in one.costs.items():
        assert two.costs[name] == cost
    # trials in start order: informed, then each start's first and second
    assert [two.trial_iterations[0]] + list(two.trial_iterations[1::2]) == list(one.trial_iterations)
    seconds = two.trial_iterations[2::2]
    assert len(seconds) == 3 and all(f"{n}, trial 2" in two.costs for n in one.costs if n != "informed")
    # the second trials are trials of their own, not copies of the first ones
    assert any(two.costs[n + ", trial 2"] != two.costs[n] for n in one.costs if n != "informed") \
        or list(seconds) != list(two.trial_iterations[1::2])


def test_the_selections_fit_memo_changes_no_number(monkeypatch):
    """LAAV's own candidates share one memo of motion fits (speed only): without it, the
    same labels, candidates' costs and descended points."""
    import laav.own_chain as V
    from explorer.demo import demo_sequence
    from laav import segment

    seq = demo_sequence()
    shared = segment(seq, 3, LaavParams(rv_missing_gate=0.0), seed=1)
    monkeypatch.setattr(V, "fit_memo", lambda points: None)
    alone = segment(seq, 3, LaavParams(rv_missing_gate=0.0), seed=1)
    np.testing.assert_array_equal(shared.labels, alone.labels)
    assert shared.voting.costs == alone.voting.costs
    assert shared.voting.descended == alone.voting.descended


def _demo_runs(monkeypatch, seed=1):
    """The demo at ``seed`` with the missing-motion gate off, on (every start explained:
    skipped), with no missing-motion start at all, and on with every start judged unexplained."""
    import laav.own_chain as V
    from explorer.demo import demo_sequence
    from laav import segment

    seq = demo_sequence()
    runs = {"off": segment(seq, 3, LaavParams(rv_missing_gate=0.0), seed=seed),
            "gated": segment(seq, 3, LaavParams(rv_missing_gate=0.5), seed=seed)}
    with monkeypatch.context() as m:
        m.setattr(V, "missing_motion_start", lambda *a, **k: None)
        runs["none"] = segment(seq, 3, LaavParams(rv_missing_gate=0.0), seed=seed)
    with monkeypatch.context() as m:
        m.setattr(V, "unexplained", lambda points, labels, C, params, fits=None:
                  np.ones(labels.size, bool))
        runs["opened"] = segment(seq, 3, LaavParams(rv_missing_gate=0.5), seed=seed)
    with monkeypatch.context() as m:  # only the first start's new motion left unexplained
        starts = []
        real = V.missing_motion_start
        m.setattr(V, "missing_motion_start", lambda *a, **k: starts.append(real(*a, **k)) or starts[-1])
        m.setattr(V, "unexplained", lambda points, labels, C, params, fits=None: starts[0] == C - 1)
        # (the starts' new motions overlap, a share near 1 leaves only the first one to run)
        runs["one"] = segment(seq, 3, LaavParams(rv_missing_gate=0.95), seed=seed)
    return runs


def test_the_missing_motion_gate_runs_only_the_starts_the_informed_result_leaves(monkeypatch):
    """``rv_missing_gate`` (ours, speed): LAAV's informed trial runs and is selected alone
    first. Every start explained (the demo): the labels and iterations of no missing-motion
    start at all, the starts named as skipped. Every start unexplained: the gate's off labels,
    candidates, costs and iterations (each trial on its own stream). One start: its two trials
    beside the informed one, the other starts skipped."""
    runs = _demo_runs(monkeypatch)
    off, gated, none, opened, one = (runs[k].voting for k in ("off", "gated", "none", "opened", "one"))
    names = tuple(f"missing motion ({g}+{h})" for g, h in ((0, 1), (0, 2), (1, 2)))
    assert off.skipped_starts == () and len(off.costs) == 7
    assert gated.skipped_starts == names and none.skipped_starts == ()
    np.testing.assert_array_equal(gated.labels, none.labels)
    assert gated.trial_iterations == none.trial_iterations and len(gated.trial_iterations) == 1
    assert gated.n_iterations < off.n_iterations / 3
    assert opened.skipped_starts == ()
    np.testing.assert_array_equal(opened.labels, off.labels)
    assert opened.costs == off.costs and opened.trial_iterations == off.trial_iterations
    assert one.skipped_starts == names[1:] and list(one.costs) == ["informed", names[0],
                                                                    names[0] + ", trial 2"]
    assert one.trial_iterations == off.trial_iterations[:3]


def test_unexplained_counts_the_points_far_from_their_motions_subspace():
    """:func:`laav.own_chain.unexplained` against a direct count: ten points of motion 1
    labelled 0 lie far (> 1 px RMS) from motion 0's rank-4 trajectory subspace, fitted by
    a plain SVD to motion 0's true points, and ten of motion 1 labelled 1 near their own;
    the same count in coordinates ten times larger with ``LaavParams.scaled(10)``."""
    from laav.own_chain import unexplained

    seq = synthetic.make_sequence(n_objects=1, n_frames=20, n_points=300, noise=0.0, rng=4)
    ones = np.flatnonzero(seq.labels == 1)
    labels = seq.labels.copy()
    labels[ones[:10]] = 0
    new = np.zeros(seq.n_points, dtype=bool)
    new[ones[:20]] = True

    def direct(g, idx):  # mean over frames of the squared distance, px^2
        X = seq.points[:, seq.labels == g].transpose(0, 2, 1).reshape(-1, (seq.labels == g).sum())
        o = X.min(axis=1, keepdims=True)  # any fixed origin: the subspace is fitted through it
        U = np.linalg.svd(X - o, full_matrices=False)[0][:, :4]
        Y = seq.points[:, idx].transpose(0, 2, 1).reshape(-1, len(idx)) - o
        return ((Y - U @ (U.T @ Y)) ** 2).sum(axis=0) / seq.n_frames

    assert (direct(0, ones[:10]) > 1.0).all() and (direct(1, ones[10:20]) < 1.0).all()
    p = LaavParams()
    assert unexplained(seq.points, labels, 2, p)[new].sum() == 10
    assert unexplained(seq.points * 10, labels, 2, p.scaled(10))[new].sum() == 10
    # pixel noise of 1 px: the median point is as far as the threshold, the test cannot tell
    noisy = seq.points + np.random.default_rng(0).normal(0, 1, seq.points.shape)
    assert unexplained(noisy, labels, 2, p) is None


def test_the_gate_runs_every_start_when_its_test_cannot_tell_or_the_trial_did_not_settle(monkeypatch):
    """The gate skips nothing, giving the gate-off labels, costs and iterations, when its
    test has no power (``unexplained`` None: the median point near the threshold, pixel
    noise; the informed trial has run alone, the others then side by side) and when LAAV's
    informed trial did not settle (here: an iteration cap of 20)."""
    import laav.own_chain as V
    from explorer.demo import demo_sequence
    from laav import segment

    seq = demo_sequence()
    off = segment(seq, 3, LaavParams(rv_missing_gate=0.0), seed=1).voting
    batches = []
    real_side = V.informed_side_by_side

    def spy(points, params, starts, extra, uses):
        batches.append(len(starts))
        return real_side(points, params, starts, extra, uses)

    monkeypatch.setattr(V, "informed_side_by_side", spy)
    with monkeypatch.context() as m:
        m.setattr(V, "unexplained", lambda *a, **k: None)
        on = segment(seq, 3, LaavParams(), seed=1).voting
    assert on.skipped_starts == () and np.array_equal(on.labels, off.labels)
    assert on.costs == off.costs and on.trial_iterations == off.trial_iterations
    assert batches == [1, 6]
    capped = LaavParams(rv_max_iter=20)
    short = segment(seq, 3, capped, seed=1).voting
    assert short.informed_converged is False and short.skipped_starts == ()
    short_off = segment(seq, 3, capped.replace(rv_missing_gate=0.0), seed=1).voting
    np.testing.assert_array_equal(short.labels, short_off.labels)
    assert short.costs == short_off.costs and len(short.costs) == 7


def test_the_pipeline_previews_the_informed_trial_while_the_starts_run(monkeypatch):
    """A live view's preview (``Pipeline``'s ``preview``) in LAAV's own chain: when the gate
    lets a start through, the result with the informed trial alone comes first -- the labels
    and trial the gate returns when it lets none through -- then the result, the same as
    without a preview (an update's too); when the gate lets none through, no preview."""
    import laav.own_chain as V
    from explorer.demo import demo_sequence
    from laav import Pipeline

    seq = demo_sequence()
    got = []
    closed = {s: Pipeline(seq, 3, seed=s, preview=got.append).result for s in (1, 3)}
    assert all(r.voting.skipped_starts for r in closed.values()) and got == []
    with monkeypatch.context() as m:
        m.setattr(V, "unexplained", lambda points, labels, C, params, fits=None:
                  np.ones(labels.size, bool))
        pipe = Pipeline(seq, 3, seed=1, preview=got.append)
        opened = {1: pipe.result}
        previews = {1: got[:]}
        got.clear()
        opened[3] = pipe.update(seed=3, preview=got.append)
        previews[3] = got[:]
        without = {s: Pipeline(seq, 3, seed=s).result for s in (1, 3)}
    for s in (1, 3):
        assert len(previews[s]) == 1, s
        pre, res, ref = previews[s][0], opened[s], without[s]
        assert pre.voting.selected == "informed" and pre.voting.skipped_starts == ()
        np.testing.assert_array_equal(pre.labels, closed[s].labels)
        assert pre.voting.trial_iterations == closed[s].voting.trial_iterations
        assert pre.atoms is res.atoms and pre.coarse is res.coarse and pre.seed == s
        assert len(res.voting.trial_iterations) == 7  # the informed trial and six for missed motions
        np.testing.assert_array_equal(res.labels, ref.labels)
        assert res.voting.costs == ref.voting.costs
        assert res.voting.trial_iterations == ref.voting.trial_iterations


def test_the_previews_own_time_is_not_the_voting_stages(monkeypatch):
    """A slow live view (its preview takes 1 s) does not count in the result's timings."""
    import time

    import laav.own_chain as V
    from explorer.demo import demo_sequence
    from laav import Pipeline

    monkeypatch.setattr(V, "unexplained", lambda points, labels, C, params, fits=None:
                        np.ones(labels.size, bool))
    slept = []
    t0 = time.perf_counter()
    res = Pipeline(demo_sequence(), 3, seed=1, preview=lambda r: (slept.append(r),
                                                                   time.sleep(1.0))).result
    wall = time.perf_counter() - t0
    assert len(slept) == 1
    assert sum(res.timings.values()) < wall - 0.9, (res.timings, wall)
    # the preview's own timings stop where it was handed over
    assert slept[0].timings["voting"] < res.timings["voting"]


def outlier_scene():
    """Three motions with 10 % of the tracks replaced by random walks (laav.synthetic's
    outliers, which keep the label of the track they replaced), and which tracks those are
    (the same scene drawn without them differs there only)."""
    seq = synthetic.make_sequence(n_objects=2, outlier_fraction=0.1, rng=6)
    clean = synthetic.make_sequence(n_objects=2, rng=6)
    return seq, (seq.points != clean.points).any(axis=(0, 2))


def test_outlier_tracks_do_not_buy_a_motion(monkeypatch):
    """Tracks that no motion explains code cheaper as a motion of their own than inside the
    motions they corrupt: without the veto the selection returns a missing-motion
    candidate that joins two real motions to give the outliers one (over 10 % of the other
    tracks wrong); with it (the default) the other tracks are right, the candidate it
    would have returned is named first among those vetoed, with the costs that decided,
    and what is returned is none of them. On this scene the veto of the trial's own labels
    descended (against the polished ones) is needed too: checking the missing-motion
    candidates alone leaves 23 % wrong."""
    import laav.own_chain as oc

    seq, out = outlier_scene()
    assert out.sum() == 30
    before = segment(seq, 3, LaavParams(rv_outlier_veto=False), seed=0)
    assert before.voting.selected.startswith("missing motion")
    assert misclassification_rate(seq.labels[~out], before.labels[~out]) > 0.1
    res = segment(seq, 3, seed=0)
    assert misclassification_rate(seq.labels[~out], res.labels[~out]) < 0.01
    kinds = [v[0] for v in res.voting.vetoed]
    name, n, informed_cost, its_cost = res.voting.vetoed[0]
    assert name == before.voting.selected and informed_cost < its_cost
    assert 0.8 * seq.n_points < n < seq.n_points  # the outliers left out, not much else
    assert res.voting.costs[name] < res.voting.costs["informed"]  # it did win over all points
    assert res.voting.selected not in kinds and "the trial's own labels, descended" in kinds
    real = oc._vetoed
    monkeypatch.setattr(oc, "_vetoed", lambda *a, always=False: real(*a, always=True) if always else None)
    part = segment(seq, 3, seed=0)  # the missing-motion candidates checked, nothing else
    assert misclassification_rate(seq.labels[~out], part.labels[~out]) > 0.1


def test_the_veto_keeps_a_descent_from_buying_outliers_a_motion(hopkins_root, monkeypatch):
    """Hopkins155 2T3RCRTP_g23 with 10 % of its tracks random walks of 3 px steps
    (``benchmarks/outliers.py``'s draw), seed 0: the descent on the joint score from the
    informed trial's labels moves 161 points to give the outliers a motion (35 % of the
    other tracks wrong); the veto keeps the labels before it (1 %). Fails without the
    descent's veto."""
    import sys
    from pathlib import Path

    import laav
    import laav.own_chain as oc

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from outliers import with_outliers

    seq = laav.load_sequence(hopkins_root / "2T3RCRTP_g23" / "2T3RCRTP_g23_truth.mat")
    noisy, out = with_outliers(seq, 0.1, 3.0)
    res = segment(noisy, 2, seed=0)
    assert "the descent" in [v[0] for v in res.voting.vetoed] and res.voting.descended == 0
    assert misclassification_rate(seq.labels[~out], res.labels[~out]) < 0.02
    real = oc._vetoed
    monkeypatch.setattr(oc, "_vetoed", lambda *a, **k: None if a[6] == "the descent" else real(*a, **k))
    off = segment(noisy, 2, seed=0)
    assert off.voting.descended > 100
    assert misclassification_rate(seq.labels[~out], off.labels[~out]) > 0.2


def test_the_veto_compares_the_points_both_labellings_explain():
    """Unit: the random walks are outliers of the true labelling (farther than 6 times the
    median and 1 px^2 from their motion's subspace: 20-41 px^2 here), few other tracks are
    (this scene's perspective leaves 8 % of them over 1 px^2, none over 6); two real motions joined
    to give the outliers a motion scores higher than the truth on the points both explain;
    one labelling against itself ties; with no motion of 8 points, None."""
    seq, out = outlier_scene()
    p = LaavParams()
    truth = seq.labels.astype(np.int64)
    flagged = outlier_points(seq.points, truth, 3, p)
    assert flagged[out].all() and flagged[~out].mean() < 0.1
    bought = np.where(truth == 2, 1, truth)
    bought[out] = 2
    n, truth_cost, bought_cost = veto(seq.points, 3, p, truth, bought)
    assert truth_cost < bought_cost
    assert joint_score(seq.points, bought, 3, p) < joint_score(seq.points, truth, 3, p)  # over all
    same = veto(seq.points, 3, p, truth, truth.copy())  # one labelling twice: a tie, no veto
    assert same[1] == same[2]
    six = np.repeat(np.arange(3), 6)  # motions of 6 points: none can be scored
    assert veto(seq.points[:, :18], 3, p, six, six.copy()) is None
