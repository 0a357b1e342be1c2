"""docs/plugins.md runs: the user's method, its ``abco bench``/``abco report`` commands."""

from __future__ import annotations

import re
import shlex
from dataclasses import fields
from pathlib import Path

import pytest
from test_bench_grid import tiny_overrides

from abco_train.bench import grid as bench
from abco_train.cli import build_parser
from abco_train.cli import main as abco_main
from abco_train.config.run import RunConfig

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "plugins.md"
# Every abco command shown in these pages must parse.
COMMAND_DOCS = [ROOT / "docs" / name for name in ("plugins.md", "benchmarking.md", "training.md")]
EXAMPLE = ROOT / "docs" / "examples" / "my_method.py"


def _blocks(language: str, doc: Path = DOC) -> list[str]:
    return re.findall(rf"^```{language}\n(.*?)^```", doc.read_text(), re.S | re.M)


def _commands(block: str) -> list[list[str]]:
    return [shlex.split(line, comments=True) for line in block.replace("\\\n", " ").splitlines()
            if line.startswith("abco ")]  # fmt: skip


def test_documented_method_is_the_example_file() -> None:
    assert _blocks("python")[0] == EXAMPLE.read_text()


def test_documented_commands_parse() -> None:
    for doc in COMMAND_DOCS:
        for block in _blocks("bash", doc):
            for argv in _commands(block):
                build_parser(argv[1:]).parse_args(argv[1:])


def test_user_method_beside_abco(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    overrides = tiny_overrides(tmp_path / "data")
    monkeypatch.chdir(tmp_path)  # the doc's relative runs/ folder lands in tmp_path
    (tmp_path / "docs" / "examples").mkdir(parents=True)
    (tmp_path / "docs" / "examples" / "my_method.py").write_text(EXAMPLE.read_text())
    tiny = [f"--{k.replace('_', '-')}={v}" for k, v in overrides.items()]
    # knn-ifo has no IDM: its own run takes the run config's settings only (a grid routes
    # the BCO family's options to the abco cells)
    settings = {f.name for f in fields(RunConfig)}
    tiny_own = [f"--{k.replace('_', '-')}={v}" for k, v in overrides.items() if k in settings]
    mine = [argv for argv in _commands(_blocks("bash")[-1])]
    assert [argv[1] for argv in mine] == ["train", "bench", "report"]
    for argv in mine:  # the same plugin file through `abco train` and `abco bench`
        if argv[1] in ("train", "bench"):  # fewer seeds, a tiny budget, else as written
            extra = tiny if argv[1] == "bench" else tiny_own
            argv = [a if a != "0-4" else "0" for a in argv] + extra + ["--quiet", "--threads=1"]
        assert abco_main(argv[1:]) == 0
    assert (tmp_path / "runs" / "knn" / "final.json").exists()
    md = (tmp_path / "runs" / "mine" / "report" / "report.md").read_text()
    main = md.split("## Table 1 re-measured", 1)[1].split("\n## ", 1)[0]
    assert "| CartPole-v1 | knn-ifo | 1 |" in main and "| CartPole-v1 | ABCO(α) | 1 |" in main
    knn = next(x for x in main.splitlines() if x.startswith("| CartPole-v1 | knn-ifo |"))
    pre, post, rl, remap = knn.strip("| ").split(" | ")[-4:]  # the pre-demos it counted
    assert int(pre.replace(",", "")) > 0 and (post, rl, remap) == ("0", "0", "0")
    # the Python API block: the same grid, now all finished, then the report
    code = _blocks("python")[-1].replace("[0, 1, 2, 3, 4]", "[0]")
    namespace = {"OVERRIDES": overrides}
    exec(compile(code, str(DOC), "exec"), namespace)
    assert namespace["files"]["report"].exists()
    log = (tmp_path / "runs" / "mine" / bench.BENCH_LOG).read_text().splitlines()
    assert '"skipped": 2' in log[-1] and '"ran": 0' in log[-1]
