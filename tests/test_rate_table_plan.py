"""`gyrojax.rate_table_plan` (issue 38): how many devices of a lot to put on the rate table for a target width of
the others' predicted scale factors (the population fit's Student-t prediction interval)."""

import math

import numpy as np
import pytest
from scipy import stats

import gyrojax as gj


def test_halfwidth_is_the_population_fits_prediction_interval():
    """t_{K-1} sqrt(s^2 (1 + 1/K) + u^2), and the fewest K that reach the target; measured on 64-device
    vcf-2018 lots (docs/results.md, learned spread ~0.087 %): K = 2 +/- 1.32 %, K = 4 +/- 0.25 % mean half-width."""
    plan = gj.rate_table_plan(0.00087, 0.002, devices=64, own=0.0001)
    k = plan.counts
    expected = stats.t.ppf(0.975, k - 1) * np.sqrt(0.00087**2 * (1 + 1 / k) + 0.0001**2)
    np.testing.assert_allclose(plan.halfwidth, expected, rtol=1e-9)
    assert k[0] == 2 and k[-1] == 63
    assert plan.recommended == int(k[np.argmax(expected <= 0.002)]) == 13  # 12 without the own 0.01 %
    assert plan.halfwidth[plan.counts == plan.recommended][0] <= 0.002 < plan.halfwidth[plan.counts ==
                                                                                        plan.recommended - 1][0]
    assert "13 rate-tabled" in plan.summary() and "fewest" in plan.summary()
    assert plan.report()["recommended"] == 13


def test_an_unreachable_target_is_said():
    plan = gj.rate_table_plan(0.00087, 0.001)
    assert plan.recommended is None
    assert "no count reaches it" in plan.summary()
    assert math.isclose(plan.halfwidth.min(), stats.t.ppf(0.975, 62) * 0.00087 * math.sqrt(1 + 1 / 63), rel_tol=1e-9)


def test_refusals():
    with pytest.raises(ValueError, match="spread must be a positive relative number"):
        gj.rate_table_plan(0.0, 0.002)
    with pytest.raises(ValueError, match="target must be a positive relative number"):
        gj.rate_table_plan(0.001, -1.0)
    with pytest.raises(ValueError, match="devices must be an integer >= 3"):
        gj.rate_table_plan(0.001, 0.002, devices=2)
    with pytest.raises(ValueError, match="own must be >= 0"):
        gj.rate_table_plan(0.001, 0.002, own=-0.1)


# -- `gyrojax plan --rate-table-target` -----------------------------------------------------------------------------

def _population_report(path, parameters, devices=64):
    """An identify report's population section as `PopulationFit.report` writes it (its parameters'
    `PopulationParameter.report()`), for the plan to read."""
    import json

    from gyrojax._identify.population import PopulationParameter

    report = {"population": {"parameters": [PopulationParameter(*p).report() for p in parameters],
                             "devices": [{"device": f"d{i}"} for i in range(devices)]}}
    path.write_text(json.dumps(report))
    return str(path)


def test_the_cli_plans_the_rate_table_from_a_spread_or_a_population_report(tmp_path, capsys):
    import json

    from gyrojax.cli import main

    out = tmp_path / "plan.json"
    assert main(["plan", "--rate-table-target", "0.2%", "--lot-spread", "0.087%", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "12 rate-tabled: the other 52 predicted +/- 0.199 %  <- fewest" in text
    assert json.loads(out.read_text())["recommended"] == gj.rate_table_plan(0.00087, 0.002).recommended == 12
    # the spread of the report's random parameter (relative, log scale), its device count as the lot size
    report = _population_report(tmp_path / "r.json", [("Ag", "1", 1.0, 1e-4, 0.0087, 1e-3, 0.0087, True)], 40)
    assert main(["plan", "--rate-table-target", "2%", "--population-report", report, "--own", "0.1%"]) == 0
    text = capsys.readouterr().out
    assert "lot spread of Ag from" in text and "0.87 %" in text and "(40 devices)" in text
    want = gj.rate_table_plan(0.0087, 0.02, devices=40, own=0.001).recommended
    assert f"{want} rate-tabled: the other {40 - want} predicted" in text


@pytest.mark.parametrize("argv, match", [
    (["--rate-table-target", "0.2%"], "exactly one of --lot-spread"),
    (["--rate-table-target", "0.2%", "--lot-spread", "1%", "DATA.csv"], "takes no DATA"),
    (["--rate-table-target", "0.2%", "--lot-spread", "1%", "--budget-min", "90"], "--budget-min belong"),
    (["--rate-table-target", "0.2%", "--lot-spread", "1%", "--devices", "2"], "devices must be an integer >= 3"),
    (["--rate-table-target", "fifty", "--lot-spread", "1%"], "relative number such as 0.2%"),
    ([], "give DATA"),
])
def test_the_cli_refuses_what_a_rate_table_plan_cannot_use(argv, match, capsys):
    from gyrojax.cli import main

    assert main(["plan", *argv]) == 2
    assert match in capsys.readouterr().err


def test_a_population_report_that_cannot_give_a_spread_is_refused_naming_the_file(tmp_path, capsys):
    from gyrojax.cli import main

    none = tmp_path / "plain.json"
    none.write_text('{"devices": []}')
    two = _population_report(tmp_path / "two.json", [("k_vf", "N/V", 1.0, 1e-3, 0.01, 1e-3, 0.01, True),
                                                     ("vcf_gain", "1", 1.0, 1e-3, 0.01, 1e-3, 0.01, True)])
    flat = _population_report(tmp_path / "flat.json", [("k_vf", "N/V", 1.0, 1e-3, 1e-5, 1e-4, 1e-5, False)])
    for path, extra, match in ((none, [], "no 'population' section"),
                               (two, [], "several random parameters (k_vf, vcf_gain)"),
                               (two, ["--random", "q_y"], "no random parameter 'q_y'"),
                               (flat, [], "not resolved from zero")):
        argv = ["plan", "--rate-table-target", "1%", "--population-report", str(path), *extra]
        assert main(argv) == 2, path
        err = capsys.readouterr().err
        assert str(path) in err and match in err, err
    assert main(["plan", "--rate-table-target", "1%", "--population-report", two, "--random", "vcf_gain"]) == 0
