"""Budget curves in ``abco report RUNS --budget-curves CURVES``: the variants ``TASK@xM`` of a
benchmark task, with the 1x points from the benchmark grid, as a table and a plot."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from abco_train.cli import main
from abco_train.report.budget_curves import variant_of

#: method -> multiple -> the score of seeds 0 and 1 (None: stopped by its method)
SCORES = {"gaifo": {1: [0.1, 0.2], 4: [0.4, 0.5], 16: [0.8, None]},
          "abco": {1: [0.6, 0.6], 4: [0.6, 0.6], 16: [0.6, 0.6]}}  # fmt: skip


def _run(root: Path, task: str, method: str, seed: int, budget: int, value: float | None
         ) -> None:  # fmt: skip
    run = root / task / method / f"seed{seed}"
    run.mkdir(parents=True)
    final = {"env": "Acrobot-v1", "method": method, "seed": seed, "task": task,
             "budget": budget, "headline": "episodes",
             "status": "ok" if value is not None else "idm_at_chance",
             "interactions": {"rl": min(budget, 5000)}}  # fmt: skip
    if value is not None:
        final["episodes"] = {"performance": value, "aer": value, "score": value,
                             "episode_scores": [value], "episodes": 1}  # fmt: skip
    (run / "final.json").write_text(json.dumps(final))
    (run / "config.json").write_text(json.dumps({"task": task}))


@pytest.fixture
def grids(tmp_path: Path) -> tuple[Path, Path]:
    main_dir, curves_dir = tmp_path / "runs", tmp_path / "curves"
    for method, by_multiple in SCORES.items():
        for multiple, values in by_multiple.items():
            root, task = ((main_dir, "acro") if multiple == 1
                          else (curves_dir, f"acro@x{multiple}"))  # fmt: skip
            for seed, value in enumerate(values):
                _run(root, task, method, seed, 1000 * multiple, value)
    _run(main_dir, "other", "gaifo", 0, 1000, 0.3)  # a task without variants
    _run(main_dir, "acro", "gaifo", 7, 1000, 0.9)  # a seed no variant ran: not on the curve
    return main_dir, curves_dir


def test_variant_names() -> None:
    assert variant_of("a@x4") == ("a", 4.0) and variant_of("a@x0.25") == ("a", 0.25)
    assert variant_of("a") is None and variant_of("a@xx") is None and variant_of("@x4") is None
    assert variant_of("a@x0") is None


def test_report_draws_the_curves(grids: tuple[Path, Path]) -> None:
    main_dir, curves_dir = grids
    assert main(["report", str(main_dir), "--budget-curves", str(curves_dir)]) == 0
    text = (main_dir / "report" / "report.md").read_text()
    assert "## Budget curves" in text and "### acro" in text
    assert "| 1,000 | 4,000 | 16,000 |" in text
    # ABCO ahead of GAIfO at 1x and 4x; at 16x GAIfO's seeds straddle it: undecided
    assert "| ABCO(α) vs GAIfO | better | better | undecided | no |" in text
    assert "0 of 1 pair(s) keep their verdict at every budget." in text
    # the curve's own row, not the benchmark's table of mean scores above it
    curves = text.split("## Budget curves", 1)[1]
    row = next(line for line in curves.splitlines() if line.startswith("| GAIfO"))
    # 1x from the benchmark grid on the variants' seeds (0, 1; not 7); the stopped run at 16x
    # counts 0: (0.8 + 0) / 2
    assert "0.150 [" in row and "0.450 [" in row and "0.400 [" in row and "1 stopped" in row
    assert (main_dir / "report" / "budget_curves.png").stat().st_size > 0
    # the variants stay out of the benchmark's task tables
    assert "### acro@x4" not in text


def test_budget_curves_without_variants_is_one_line(grids: tuple[Path, Path],
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    main_dir, _ = grids
    assert main(["report", str(main_dir), "--budget-curves", str(main_dir)]) == 2
    err = capsys.readouterr().err.strip()
    assert "holds no task named TASK@xMULTIPLE" in err and len(err.splitlines()) == 1


def test_a_variant_with_the_wrong_budget_is_refused(grids: tuple[Path, Path],
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    main_dir, curves_dir = grids
    _run(curves_dir, "acro@x2", "abco", 0, 1000, 0.6)  # records the 1x budget, not 2,000
    assert main(["report", str(main_dir), "--budget-curves", str(curves_dir)]) == 2
    err = capsys.readouterr().err.strip()
    assert "acro@x2: abco's records carry budget 1,000, not 2,000" in err
    assert len(err.splitlines()) == 1
    assert main(["report", str(main_dir), "--budget-curves", str(main_dir / "none")]) == 2
    assert "is not a folder" in capsys.readouterr().err
