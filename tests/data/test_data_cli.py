"""The data command line: list, info, generate, verify (download/push are the hub's)."""

import argparse
import subprocess
import sys

import h5py

from abco_data import cli


def test_list(capsys):
    assert cli.main(["list"]) == 0
    out = capsys.readouterr().out
    assert out.count("abco/") == 26 and "abco/maze10x10-pre-v0" in out
    assert "abco/lunarlander-expert-v1" in out  # the classic expert sets' version 1
    assert "abco/lunarlander-expert-v0" in out and "abco/lunarlander-pre-v0" in out
    assert "abco/maze5x5-pre-start-v0" in out  # the authors' regime's pre-demonstrations


def test_generate_info_verify(tmp_path, capsys):
    out_path = tmp_path / "m.hdf5"
    args = ["generate", "abco/maze3x3-expert-v0", "--out", str(out_path), "--quiet",
            "--set", "layouts=1", "--set", "solutions_per_layout=2",
            "--set", "reference_episodes=3"]
    assert cli.main(args) == 0
    captured = capsys.readouterr()
    assert "sha256" in captured.out and captured.err == ""  # --quiet: no progress bar
    assert cli.main(["info", str(out_path)]) == 0
    out = capsys.readouterr().out
    assert "episodes:    2" in out and "observations palette4 (5 colours)" in out
    assert cli.main(["verify", str(out_path)]) == 0
    out = capsys.readouterr().out
    assert out.startswith("OK ") and "match the bytes abco generates" in out
    assert cli.main(["verify", str(out_path), "--sha256", "0" * 64]) == 1
    assert "do not match" in capsys.readouterr().err


def test_verify_reports_bad_files(tmp_path, capsys):
    bad = tmp_path / "bad.hdf5"
    bad.write_bytes(b"not hdf5 at all")
    assert cli.main(["verify", str(bad)]) == 1
    err = capsys.readouterr().err
    assert "bad.hdf5" in err and "not a readable HDF5 file" in err
    plain = tmp_path / "plain.hdf5"
    with h5py.File(plain, "w") as f:
        f.attrs["format"] = "abco-dataset"
        f.attrs["format_version"] = 7
    assert cli.main(["verify", str(plain)]) == 1
    assert "format_version 7" in capsys.readouterr().err


def test_unknown_id_and_bad_override(tmp_path, capsys):
    assert cli.main(["info", "abco/nope-v0"]) == 2
    assert "known ids" in capsys.readouterr().err
    assert cli.main(["generate", "abco/maze3x3-pre-v0", "--out", str(tmp_path / "x.hdf5"),
                     "--set", "colour=1", "--quiet"]) == 2
    assert "colour" in capsys.readouterr().err
    assert cli.main(["generate", "abco/maze3x3-pre-v0", "--set", "layouts=1"]) == 2
    assert "--set needs --out" in capsys.readouterr().err
    assert cli.main(["verify", str(tmp_path / "nothere.hdf5")]) == 2
    assert "nothere.hdf5: no such dataset file" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_mounts_under_another_program():
    parser = argparse.ArgumentParser(prog="abco")
    cli.add_subcommands(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["data", "verify", "x.hdf5"])
    assert args.command == "data" and args.data_command == "verify" and callable(args.func)


def test_python_dash_m():
    out = subprocess.run([sys.executable, "-m", "abco_data", "list"], capture_output=True,
                         text=True, check=True)
    assert "abco/cartpole-expert-v0" in out.stdout


def test_info_refuses_a_layout_count_below_one_even_uncached(tmp_path, capsys):
    argv = ["info", "abco/maze5x5-expert-v0", "--cache-dir", str(tmp_path), "--layouts", "0"]
    assert cli.main(argv) == 2
    assert capsys.readouterr().err.strip() == "error: --layouts must be >= 1, got 0"
