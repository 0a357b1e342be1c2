"""``abco tune``: every method's search space inside its option's bounds, the same number of
trials for every method on a tiny track (trial 0 the defaults, the rest inside the space, on
validation seeds only), a resume that adds trials without re-running any, an interrupted trial
run again with its settings, the record read back as untrusted input, and the report's
tuning-effort section."""

from __future__ import annotations

import json
from dataclasses import asdict, fields
from pathlib import Path

import pytest
from train_testing import one_error_line

from abco_train.cli import main
from abco_train.methods.registry import builtin_options, options_class
from abco_train.report.runs import ReportError
from abco_train.report.tuning_effort import section
from abco_train.tune.record import FORMAT, TrialRow, read_trials
from abco_train.tune.space import method_space, suggest
from abco_train.tune.study import _requeue_unfinished

optuna = pytest.importorskip("optuna")

TRACK = """
[track]
name = "tiny"
methods = ["random", "expert", "bc", "bco"]
validation_seeds = "100"
test_seeds = "1000"

[[task]]
name = "cp"
env = "CartPole-v1"
budget = 5000
settings = { eval_episodes = 2, pre_transitions = 400, expert_episodes = 2, iterations = 1 }
"""


@pytest.mark.parametrize("method", sorted(builtin_options()))
def test_search_ranges_lie_inside_the_options_bounds(method: str) -> None:
    from abco_train.config.run import RunConfig

    meta = {f.name: f.metadata for cls in (RunConfig, options_class(method)) for f in fields(cls)}
    for name, (search, kind) in method_space(method).items():
        bounds = meta[name]
        if search.choices:
            assert set(search.choices) <= set(bounds.get("choices", search.choices)), name
            continue
        assert search.low < search.high, name
        if "min" in bounds:
            assert search.low > bounds["min"] or (
                search.low == bounds["min"] and not bounds.get("exclusive")), name
        if "max" in bounds:
            assert search.high <= bounds["max"], name
        assert kind in (int, float), name


def test_bc_searches_no_idm_option() -> None:
    assert sorted(method_space("bc")) == ["lr", "patience_checks", "policy_epochs"]
    assert "idm_epochs" in method_space("abco")


@pytest.mark.parametrize(("method", "resolved", "searched"), [
    ("bco", [{"schedule": "converged"}], {"lr", "patience_checks"}),
    ("bco", [{"schedule": "converged"}, {"schedule": "epochs"}],  # one task reads the epochs
     {"lr", "patience_checks", "idm_epochs", "idm_patience", "policy_epochs"}),
    ("ilpo", [{"schedule": "converged", "policy_steps": None}],
     {"lr", "patience_checks", "exp_weight", "relax", "remap"}),
    ("ilpo", [{"schedule": "steps", "policy_steps": 1000}],  # G, then pi: no joint weight
     {"lr", "train_steps", "relax", "remap"}),
    ("dilo", [{"schedule": "steps"}], {"lr", "lam", "temperature"}),
])
def test_a_family_searches_only_what_its_tasks_read(method, resolved, searched) -> None:
    assert set(method_space(method, resolved)) == searched


def test_the_headline_families_search_what_their_runs_read() -> None:
    from abco_train.bench.tasks import load_track
    from abco_train.tune.space import resolved_options
    from abco_train.tune.study import family_tasks

    track = load_track("headline")

    def space(method: str, family: str) -> set[str]:
        return set(method_space(method, resolved_options(track, method,
                                                         family_tasks(track, family))))

    # classic: ILPO and LAPO converge on every task; MountainCar's authors' regime keeps the
    # BCO family's epochs; mazes: ILPO trains G, then pi, and LAPO keeps its step counts
    assert "train_steps" not in space("ilpo", "classic")
    assert "patience_checks" in space("lapo", "classic")
    assert {"idm_epochs", "patience_checks"} <= space("abco", "classic")
    assert "exp_weight" not in space("ilpo", "maze") and "train_steps" in space("ilpo", "maze")
    assert "patience_checks" not in space("lapo", "maze")


def _tune(tmp_path: Path, trials: int, *extra: str) -> Path:
    track = tmp_path / "track.toml"
    track.write_text(TRACK)
    out = tmp_path / "tuning"
    argv = ["tune", "--track", str(track), "--family", "classic", "--methods", "bc,bco",
            "--trials", str(trials), "--out", str(out), "--jobs", "1", "--quiet", *extra]
    assert main(argv) == 0
    return out


def test_every_method_gets_the_same_trials_and_a_resume_adds_only_new_ones(tmp_path: Path):
    out = _tune(tmp_path, 3)
    rows, damaged = read_trials(out / "trials.jsonl")
    assert damaged == 0
    by_method = {m: [r for r in rows if r.method == m] for m in ("bc", "bco")}
    assert {m: len(r) for m, r in by_method.items()} == {"bc": 3, "bco": 3}
    for method, mine in by_method.items():
        assert mine[0].defaults and mine[0].params == {}  # trial 0: the defaults
        space = method_space(method)
        for row in mine[1:]:  # CartPole converges: the epoch counts, which it never reads,
            assert set(row.params) == {"lr", "patience_checks"}  # are not searched
            assert not row.defaults
            for name, value in row.params.items():
                search, _ = space[name]
                assert search.low <= value <= search.high, (name, value)
        assert all(r.seeds == [100] and r.test_seeds == [1000] for r in mine)
        assert all(list(r.runs) == ["cp/seed100"] and r.runs["cp/seed100"] is not None
                   for r in mine)  # fmt: skip
    choices = json.loads((out / "choices.json").read_text())["choices"]
    for method, mine in by_method.items():
        kept = choices[method]["classic"]
        assert kept["trials"] == 3 and kept["value"] == max(r.value for r in mine)
    first = out / "classic" / "bc" / "trial000" / "cp" / "bc" / "seed100" / "final.json"
    stamp = first.stat().st_mtime_ns
    _tune(tmp_path, 4)
    rows, _ = read_trials(out / "trials.jsonl")
    assert sorted(r.trial for r in rows if r.method == "bc") == [0, 1, 2, 3]
    assert first.stat().st_mtime_ns == stamp  # finished trials are not run again
    assert "| classic | bco | 4 |" in (out / "tuning.md").read_text()
    assert "Validation seeds classic 100 (" in (out / "tuning.md").read_text()


def test_the_record_names_each_familys_own_seeds() -> None:
    from abco_train.tune.record import _seeds_by_family

    rows = [TrialRow("headline", family, "bc", 0, True, 0.5, seeds=seeds)
            for family, seeds in (("maze", [100]), ("classic", [101, 100, 102]))]
    assert _seeds_by_family(rows) == "classic 100, 101, 102; maze 100"
    assert _seeds_by_family([]) == "none yet"


def test_an_interrupted_trial_is_queued_again_with_its_settings() -> None:
    study = optuna.create_study(direction="maximize")
    _requeue_unfinished(study)  # a new study: its defaults first
    defaults = study.ask()
    assert defaults.user_attrs["defaults"]
    study.tell(defaults, 0.5)
    space = method_space("bco")
    lost = study.ask()
    drawn = suggest(lost, space)
    lost.set_user_attr("folder", "trial001")  # the process dies here: the trial stays running
    _requeue_unfinished(study)
    assert study.trials[1].state == optuna.trial.TrialState.FAIL
    again = study.ask()
    assert suggest(again, space) == drawn and again.user_attrs["folder"] == "trial001"


def _row(method: str, trial: int, value: float, seeds: list[int]) -> dict:
    return {"format": FORMAT, **asdict(TrialRow("tiny", "classic", method, trial, trial == 0,
                                                 value, seeds=seeds, test_seeds=[1000]))}


def test_report_shows_the_tuning_effort_and_flags_what_a_reviewer_would(tmp_path: Path):
    lines = [_row("bco", k, 0.1 * k, [100]) for k in range(8)]
    lines += [_row("abco", k, 0.2, [100]) for k in range(3)]
    lines += [_row("abco", 3, 0.9, [100, 1000])]  # a trial on a test seed
    text = "\n".join(json.dumps(r) for r in lines) + "\n{not json\n" + json.dumps(
        {**lines[0], "value": float("nan")}.__repr__()) + "\n"
    (tmp_path / "trials.jsonl").write_text(text)
    md = "\n".join(section(tmp_path, ["bco", "abco"]))
    assert "| bco | classic | 8 | 0.000 | 0.700 (7) | 100 |" in md
    assert "| abco | classic | 4 | 0.200 | 0.900 (3) | 100, 1000 |" in md
    assert "classic: **unequal tuning**: bco 8, abco 4." in md
    assert "**Trials on test seeds**: abco (classic, trial 3)." in md
    assert "2 damaged line(s)" in md
    (tmp_path / "trials.jsonl").write_text("\n".join(json.dumps(r) for r in lines[:8]) + "\n")
    assert "classic: every method of the grid had 8 trials." in "\n".join(
        section(tmp_path, ["bco"]))
    with pytest.raises(ReportError, match="cannot read"):
        section(tmp_path / "none", ["bco"])


@pytest.mark.parametrize(("argv", "message"), [
    (["--family", "maze"], "track tiny has no maze task"),
    (["--family", "classic", "--methods", "bco"], None),  # a track without validation seeds
    (["--family", "classic", "--methods", "nope"], "nope"),
    (["--family", "classic", "--seeds", "100,1000"],  # a test seed
     "--seeds 1000: not among track tiny's validation seeds"),
])  # fmt: skip
def test_tune_refusals_are_one_line(tmp_path: Path, capsys, argv, message) -> None:
    track = tmp_path / "track.toml"
    track.write_text(TRACK)
    if message is None:
        track.write_text(TRACK.replace('validation_seeds = "100"', ""))
        message = "names no validation seeds"
    assert main(["tune", "--track", str(track), "--out", str(tmp_path / "t"), *argv]) == 2
    one_error_line(capsys.readouterr().err, message)
    assert not (tmp_path / "t" / "trials.jsonl").exists()


def test_a_study_keeps_its_seeds(tmp_path: Path, capsys) -> None:
    """``--seeds`` picks some validation seeds for every trial; a resume on others would score
    trials on different runs, and is refused before any runs."""
    track = tmp_path / "track.toml"
    track.write_text(TRACK.replace('validation_seeds = "100"', 'validation_seeds = "100-101"'))
    out = tmp_path / "t"
    argv = ["tune", "--track", str(track), "--family", "classic", "--methods", "bc", "--out",
            str(out), "--jobs", "1", "--quiet", "--trials", "1"]  # fmt: skip
    assert main([*argv, "--seeds", "101"]) == 0
    rows, _ = read_trials(out / "trials.jsonl")
    assert [(r.seeds, list(r.runs)) for r in rows] == [([101], ["cp/seed101"])]
    before = (out / "trials.jsonl").read_bytes()
    assert main([*argv[:-1], "2"]) == 2  # all the validation seeds: 100 and 101
    one_error_line(capsys.readouterr().err, "ran its trials on seeds 101")
    assert (out / "trials.jsonl").read_bytes() == before
    assert not (out / "classic" / "bc" / "trial001").exists()


def _choices(tmp_path: Path, **changes) -> Path:
    entry = {"run_settings": {"lr": 0.002}, "method_options": {"policy_epochs": 3}}
    data = {"format": FORMAT, "track": "tiny", "choices": {"bc": {"classic": entry}}, **changes}
    path = tmp_path / "choices.json"
    path.write_text(json.dumps(data))
    return path


def test_a_grid_runs_with_the_chosen_settings_of_each_method(tmp_path: Path) -> None:
    track = tmp_path / "track.toml"
    track.write_text(TRACK)
    out = tmp_path / "grid"
    argv = ["bench", "--track", str(track), "--seeds", "test", "--methods", "bc,random",
            "--choices", str(_choices(tmp_path)), "--out", str(out), "--quiet", "--jobs", "1"]
    assert main(argv) == 0
    bc = json.loads((out / "cp/bc/seed1000/config.json").read_text())
    random = json.loads((out / "cp/random/seed1000/config.json").read_text())
    assert bc["lr"] == 0.002 and bc["method_options"]["policy_epochs"] == 3
    assert random["lr"] != 0.002  # another method's choice is not this one's


def test_a_budget_curve_takes_the_choices_of_the_track_it_varies(tmp_path: Path) -> None:
    track = tmp_path / "track.toml"
    track.write_text(TRACK)
    out = tmp_path / "curves"
    argv = ["bench", "--track", str(track), "--seeds", "test", "--methods", "bc",
            "--budget-multiples", "2", "--choices", str(_choices(tmp_path)), "--out", str(out),
            "--quiet", "--jobs", "1"]  # fmt: skip
    assert main(argv) == 0
    bc = json.loads((out / "cp@x2/bc/seed1000/config.json").read_text())
    assert bc["lr"] == 0.002 and bc["budget"] == 10000  # the task's 5,000, twice


@pytest.mark.parametrize(("changes", "message"), [
    ({"track": "other"}, "tuned on track 'other'"),
    ({"format": 0}, "not an `abco tune` choices.json"),
    ({"choices": {"bc": {"classic": {"run_settings": {"lr": 0.5}}}}}, "lr = 0.5 is outside"),
    ({"choices": {"bc": {"classic": {"method_options": {"idm_epochs": 4}}}}},
     "no tunable setting 'idm_epochs'"),
    ({"choices": {"bc": {"vectors": {}}}}, "bad family 'vectors'"),
    ({"choices": {"nope": {"classic": {}}}}, "nope"),
])  # fmt: skip
def test_choices_from_elsewhere_are_checked(tmp_path: Path, capsys, changes, message) -> None:
    track = tmp_path / "track.toml"
    track.write_text(TRACK)
    argv = ["bench", "--track", str(track), "--methods", "bc", "--choices",
            str(_choices(tmp_path, **changes)), "--out", str(tmp_path / "grid")]
    assert main(argv) == 2
    one_error_line(capsys.readouterr().err, message)
    assert not (tmp_path / "grid").exists()
