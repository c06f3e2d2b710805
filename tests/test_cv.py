"""benchmarks/cv.py: folds grouped by source video, choices made on the other folds only."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import cv  # noqa: E402


def test_a_video_and_its_subsets_share_one_fold():
    names = ["1R2RC", "1R2RC_g12", "1R2RC_g13", "1R2RC_g23", "cars1", "arm", "cars2_06",
             "cars2_06_g23", "kanatani1", "people1"]
    fold = cv.folds_by_video(names, 3, seed=0)
    assert cv.video_of("1R2RC_g13") == "1R2RC" and cv.video_of("cars2_06") == "cars2_06"
    assert len({fold[n] for n in names if n.startswith("1R2RC")}) == 1
    assert fold["cars2_06"] == fold["cars2_06_g23"]
    assert set(fold.values()) == {0, 1, 2}


def test_each_fold_is_judged_by_a_choice_made_without_it():
    # config "a" is best overall but fails v0, where only "b" works: the fold holding v0
    # must still be given "a" (chosen on the other folds), so its held-out error is a's
    seqs = [f"v{i}" for i in range(10)]
    errors = {"a": {s: 0.0 for s in seqs}, "b": {s: 10.0 for s in seqs}}
    errors["a"]["v0"], errors["b"]["v0"] = 50.0, 0.0
    res = cv.cross_validate(errors, dict.fromkeys(seqs, 2), n_folds=5)
    assert all(best == "a" for _, best, _, _ in res["folds"])
    assert res["cv"][2] == 5.0  # 50 % on v0, held out, 0 elsewhere: mean 5.0
    assert res["all_data"]["a"][2] == 5.0 and res["all_data"]["b"][2] == 9.0


def test_runs_from_several_files_take_each_configuration_from_the_first_that_has_it(tmp_path, capsys):
    """``--runs a.csv,b.csv``: a configuration in both (a rerun of the same code) is read
    from the first file only, never its runs twice; one only in the second is read there."""
    head = "config,sequence,motions,seed,error\n"
    rows = "".join(f"{{c}},v{i},2,0,{{e}}\n" for i in range(10))
    (tmp_path / "a.csv").write_text(head + rows.format(c="a", e=1.0))
    (tmp_path / "b.csv").write_text(head + rows.format(c="a", e=9.0) + rows.format(c="b", e=0.0))
    assert cv.main(["--runs", f"{tmp_path / 'a.csv'},{tmp_path / 'b.csv'}", "--grid", "a,b"]) == 0
    out = capsys.readouterr().out
    assert "| all data, a | 1.00 | nan | 1.00 |" in out  # a's from a.csv alone (no 3 motions)
    assert "| all data, b | 0.00 | nan | 0.00 |" in out
