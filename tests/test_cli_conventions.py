"""The command line's conventions, every command alike: ``--quiet`` and ``--no-progress``,
progress only on a terminal, numeric options range-checked before any work."""

import subprocess
import sys

import pytest

from pnlviz.commands import build_parser, main


def commands():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    return sub.choices


def test_every_command_takes_quiet_and_no_progress():
    for name, command in commands().items():
        options = {o for a in command._actions for o in a.option_strings}
        assert {"--quiet", "-q", "--no-progress"} <= options, name


@pytest.mark.parametrize("argv, said", [
    (["calibrate", "--workers", "-1"], "argument --workers: expected a whole number >= 0, got -1"),
    (["calibrate", "--alpha", "5"], "argument --alpha: expected a number in [0, 1], got 5"),
    (["calibrate", "--alpha", "nan"], "argument --alpha: expected a number in [0, 1], got nan"),
    (["qa", "--top", "-1"], "argument --top: expected a whole number >= 0, got -1"),
    (["qa", "--tol", "0"], "argument --tol: expected a number in (0, 1000], got 0"),
    (["eval", "--thresholds", "5", "-2"], "argument --thresholds: expected a number in (0, 1000], got -2"),
    (["labels", "--workers", "two"], "argument --workers: expected a whole number, got 'two'"),
    (["detect", "--kp-threshold", "1.5"], "argument --kp-threshold: expected a number in [0, 1], got 1.5"),
    (["detect", "--batch", "0"], "argument --batch: expected a whole number in 1..256, got 0"),
    (["export", "--gate-px", "-3"], "argument --gate-px: expected a number in (0, 1000], got -3"),
    (["render", "--fps", "inf"], "argument --fps: expected a number in (0, 1000], got inf"),
    (["serve", "--port", "70000"], "argument --port: expected a whole number in 0..65535, got 70000"),
    (["sheet", "-n", "0"], "argument -n: expected a whole number >= 1, got 0"),
    (["synth", "--out", "x", "-n", "2", "--workers", "0"], "argument --workers: expected a whole number >= 1, got 0"),
])
def test_a_number_out_of_range_is_refused_naming_the_option(argv, said, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    assert said in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []  # refused before any work: nothing written


def test_quiet_prints_nothing_but_does_the_work(tmp_path, capsys):
    assert main(["synth", "--out", str(tmp_path / "a"), "-n", "1", "--size", "320x180"]) == 0
    assert "wrote 1 frames" in capsys.readouterr().out
    assert main(["synth", "--out", str(tmp_path / "b"), "-n", "1", "--size", "320x180", "--quiet"]) == 0
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == ""
    assert sorted(p.name for p in (tmp_path / "b").iterdir()) == sorted(p.name for p in (tmp_path / "a").iterdir())
    assert main(["validate", "--data", str(tmp_path / "b"), "-q"]) == 0 and capsys.readouterr().out == ""


def test_a_log_redirected_to_a_file_gets_no_progress_bar(tmp_path):
    """stderr to a file (not a terminal): the bar's carriage returns and percentages stay out of
    the log; the summary line is still printed."""
    log = tmp_path / "log.txt"
    with open(log, "w") as err:
        run = subprocess.run([sys.executable, "-m", "pnlviz.cli", "synth", "--out", str(tmp_path / "s"), "-n", "3",
                              "--size", "320x180"], stdout=subprocess.PIPE, stderr=err, text=True, timeout=300)
    assert run.returncode == 0 and "wrote 3 frames" in run.stdout
    text = log.read_text()
    assert "\r" not in text and "%|" not in text and "it/s" not in text


def test_the_help_names_no_path_of_a_checkout():
    """Installed from the wheel there is no assets/, benchmarks/ or scripts/ folder and no clone
    to `pip install -e`: the help of every command says what to do without them."""
    import re

    from pnlviz.detect.default import DEFAULT_MODEL

    for name, command in commands().items():
        text = command.format_help().replace(str(DEFAULT_MODEL), "<the shipped model>")  # where it is installed
        assert not re.search(r"assets/|benchmarks/|scripts/|examples/|pip install -e", text), (name, text)
