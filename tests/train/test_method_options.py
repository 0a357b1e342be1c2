"""Method options: typed, checked, flags of their own, routed per cell, read from old folders."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import pytest

from abco_train.bench.cells import Cell, cell_config, check_method_options
from abco_train.cli import _option_flags, build_parser, main
from abco_train.config.fields import ConfigError, MethodOptions, option
from abco_train.config.run import MOVED_TO_METHOD_OPTIONS, RunConfig
from abco_train.harness.run_folder import finished_result
from abco_train.methods.bco.options import BCOOptions
from abco_train.methods.registry import (
    available,
    builtin_options,
    config_from_record,
    get_method,
    identity,
    resolve_config,
)


@dataclass
class _Demo(MethodOptions):
    flag_prefix = "demo-"
    steps: int = option("steps", 10, min=1, max=100)
    rate: float = option("rate", 0.5, min=0.0, exclusive=True)
    mode: str = option("mode", "a", choices=("a", "b"))


@pytest.mark.parametrize(("given", "message"), [
    ({"steps": 0}, "--demo-steps must be >= 1, got 0"),
    ({"steps": 101}, "--demo-steps must be <= 100, got 101"),
    ({"steps": True}, "--demo-steps must be an integer, got True"),
    ({"steps": 2.5}, "--demo-steps must be an integer, got 2.5"),
    ({"rate": 0.0}, "--demo-rate must be > 0.0, got 0.0"),
    ({"rate": float("nan")}, "--demo-rate must be a finite number, got nan"),
    ({"mode": "c"}, "--demo-mode must be one of a, b, got 'c'"),
    ({"stpes": 3}, "unknown demo option\\(s\\) stpes; known: mode, rate, steps"),
])  # fmt: skip
def test_options_are_checked_by_their_fields(given: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        _Demo.resolve(given, {}, "demo")
    assert _Demo.resolve({"rate": 1}, {}, "demo") == _Demo(10, 1, "a")  # an int is a number


def test_every_builtin_method_names_its_options_class() -> None:
    table = builtin_options()
    assert set(table) == set(available()) - {m for m in available() if m not in table}
    for name, cls in table.items():
        assert get_method(name).Options is cls, name


def test_unknown_options_are_refused_for_every_method() -> None:
    for method in ("abco", "bc", "iupe", "ilpo", "gaifo"):
        with pytest.raises(ConfigError, match=f"unknown {method} option"):
            resolve_config(RunConfig(env="CartPole-v1", method=method,
                                     method_options={"no_such_option": 1}))  # fmt: skip


def test_resolved_options_are_stored_whole() -> None:
    cfg = resolve_config(RunConfig(env="AbcoMaze10x10-v0", method_options={"idm_epochs": 7}))
    assert cfg.method_options == asdict(BCOOptions(
        idm_input="difference", idm_epochs=7, idm_patience=1, idm_samples=20_000,
        policy_epochs=10, first_epochs_factor=3, schedule="converged", check_updates=100,
        patience_checks=5, min_fit_updates=500, max_fit_updates=20_000))  # fmt: skip


def test_flags_follow_the_method(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["train", "--method", "ilpo", "--ilpo-latents", "5"]
    args = build_parser(argv).parse_args(argv)
    assert _option_flags(args) == {"ilpo-latents": 5}  # ILPO's own flag, its prefix kept
    with pytest.raises(SystemExit):
        build_parser(["train", "--method", "ilpo"]).parse_args(["train", "--idm-epochs", "2"])
    capsys.readouterr()
    assert main(["train", "--env", "CartPole-v1", "--method-options", '{"latent": 3}',
                 "--method", "ilpo"]) == 2  # fmt: skip
    assert capsys.readouterr().err.strip() == ("error: unknown ilpo option(s) latent; known: "
                                               + ", ".join(sorted(
                                                   builtin_options()["ilpo"].names())))


def test_a_grid_gives_each_method_its_own_options(tmp_path: Path) -> None:
    options = {"idm_epochs": 2}
    abco = cell_config(Cell("CartPole-v1", "abco", 0), tmp_path, options)
    ilpo = cell_config(Cell("CartPole-v1", "ilpo", 0), tmp_path, {}, 1, {"latents": 3, **options})
    assert abco["method_options"] == {"idm_epochs": 2} and "idm_epochs" not in abco
    assert ilpo["method_options"] == {"latents": 3}
    check_method_options(["abco", "ilpo"], options, {"latents": 3})
    with pytest.raises(ConfigError, match="no method of the grid \\(gaifo\\) has option"):
        check_method_options(["gaifo"], options, None)


def test_a_methods_own_flag_reaches_that_method_only(tmp_path: Path) -> None:
    """``--lapo-schedule steps`` in a grid with the BCO family sets LAPO's schedule and
    nobody else's (a plain ``schedule`` reaches every method that has one, LAPO's flag wins)."""
    argv = ["bench", "--envs", "CartPole-v1", "--methods", "bco,lapo", "--out", "x",
            "--lapo-schedule", "steps", "--schedule", "epochs"]
    flags = _option_flags(build_parser(argv).parse_args(argv))
    assert flags == {"lapo-schedule": "steps", "schedule": "epochs"}
    check_method_options(["bco", "lapo"], None, flags)
    configs = {m: cell_config(Cell("CartPole-v1", m, 0), tmp_path, {}, 1, flags)
               for m in ("bco", "lapo", "dilo")}  # fmt: skip
    assert configs["bco"]["method_options"] == {"schedule": "epochs"}
    assert configs["lapo"]["method_options"] == {"schedule": "steps"}
    assert configs["dilo"]["method_options"] == {"schedule": "epochs"}
    with pytest.raises(ConfigError, match="has option\\(s\\) lapo-schedule"):
        check_method_options(["bco"], None, {"lapo-schedule": "steps"})


def test_a_folder_from_before_the_options_moved_is_still_recognised(tmp_path: Path) -> None:
    new = resolve_config(RunConfig(env="CartPole-v1", method="bco", run_dir=str(tmp_path)))
    old = {k: v for k, v in asdict(new).items() if k != "method_options"}
    old.update(new.method_options)  # the settings stood at the top level then
    old["method_options"] = {}
    # the moved settings, and options added since (idm_reinit, the schedule's), which old
    # folders lack
    added = {"idm_reinit", "schedule", "check_updates", "patience_checks", "min_fit_updates",
             "max_fit_updates"}  # fmt: skip
    assert set(new.method_options) - set(MOVED_TO_METHOD_OPTIONS) == added
    assert set(MOVED_TO_METHOD_OPTIONS) <= set(new.method_options)
    for name in added:
        old.pop(name)
    (tmp_path / "config.json").write_text(json.dumps(old))
    final = {"env": "CartPole-v1", "method": "bco", "seed": 0, "status": "ok",
             "episodes": {"performance": 1.0, "aer": 500.0, "success_rate": 1.0, "episodes": 5}}
    (tmp_path / "final.json").write_text(json.dumps(final))
    assert identity(old) == identity(asdict(new))
    assert finished_result(tmp_path, asdict(new)) == final
    assert resolve_config(config_from_record(old)).method_options == new.method_options
    changed = new.replace(method_options={**new.method_options, "idm_epochs": 9})
    assert finished_result(tmp_path, asdict(changed)) is None
    ilpo = {**old, "method": "ilpo"}  # the BCO settings were filled in for every method
    assert "idm_epochs" not in config_from_record(ilpo).method_options


def test_every_count_of_every_method_has_an_upper_bound() -> None:
    import typing
    from dataclasses import fields as dc_fields

    from abco_train.config.fields import base_type

    for cls in set(builtin_options().values()):
        hints = typing.get_type_hints(cls)
        for f in dc_fields(cls):
            if base_type(hints[f.name]) is int:
                assert f.metadata.get("max") is not None, f"{cls.__name__}.{f.name}"
    with pytest.raises(ConfigError, match="--gaifo-rl-steps must be <= 100,000,000, got"):
        resolve_config(RunConfig(env="CartPole-v1", method="gaifo",
                                 method_options={"rl_steps": 10**12}))  # fmt: skip
