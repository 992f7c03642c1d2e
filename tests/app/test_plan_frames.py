"""dockfactory plan-frames: counts from given figures or from a config's geometry; bad input is
one line and exit 2."""
import pytest

from dockfactory.cli import main


def test_given_figures_print_a_count_per_component(capsys):
    assert main(["plan-frames", "--rmse", "x=4.5", "--rmse", "y=0.13", "--rmse", "alpha=0.02"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 4 and lines[0].startswith("localization: x: expected 4.5 mm against 5 mm (margin 0.90)")
    n = int(lines[-1].split(": ")[1].split()[0])
    assert n > 100 and lines[-1].endswith("test frames prove every gated component conforms")


def test_a_configs_geometry_gives_the_figures(capsys):
    assert main(["plan-frames", "--config", "smoke", "--centre-noise", "0.1", "--max-frames", "5"]) == 0
    low = capsys.readouterr().out
    assert main(["plan-frames", "--config", "smoke", "--centre-noise", "0.1", "--max-frames", "5",
                 "--bound-factor", "3"]) == 0
    high = capsys.readouterr().out
    assert "estimation: " in low and "localization: " in low

    def x_of(text):
        line = next(li for li in text.splitlines() if li.startswith("localization: x: expected"))
        return float(line.split("expected ")[1].split()[0])
    assert x_of(high) == pytest.approx(3 * x_of(low), rel=1e-3)


@pytest.mark.parametrize("argv, words", [
    ([], "give --rmse COMPONENT=VALUE"),
    (["--rmse", "x0.4"], "--rmse: expected COMPONENT=VALUE"),
    (["--rmse", "q=0.4"], "--rmse: expected COMPONENT=VALUE"),
    (["--rmse", "x=-1"], "--rmse: x: expected a finite number > 0"),
    (["--rmse", "x=nan"], "--rmse: x: expected a finite number > 0"),
    (["--rmse", "x=1", "--rmse", "x=2"], "x is given twice"),
    (["--rmse", "x=1"], "gates y but no expected figure"),
    (["--config", "smoke"], "--config needs --centre-noise"),
    (["--centre-noise", "0.1", "--rmse", "x=1"], "--centre-noise needs --config"),
    (["--config", "smoke", "--centre-noise", "0.1", "--rmse", "x=1"], "not both"),
    (["nope.toml", "--rmse", "x=1"], "nope.toml"),
])
def test_bad_input_is_one_line_exit_2(argv, words, capsys):
    assert main(["plan-frames", *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0], err
