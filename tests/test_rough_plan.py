"""Issue 36's rough edges of the planner, the testability rule and the plots: the scale factor on the data
given follows identify's verdict, the budget is bounded, the plan warns where its own model or design falls
short, one rule says what is testable (diagnose and plan), and the plots rank, label and show what they claim."""

import math
import pathlib
import types

import matplotlib


matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import gyrojax as gj  # noqa: E402
import gyrojax.plot as gplot  # noqa: E402
from gyrojax._cli.demo_job import table2_path  # noqa: E402
from gyrojax._diagnose.score import score_candidates, separating_sweep  # noqa: E402
from gyrojax._numerics.testability import MIN_TYPICAL_CHI2, is_testable, separates  # noqa: E402
from gyrojax._plan.plan import MAX_BUDGET_MIN, _warnings  # noqa: E402
from gyrojax.cli import main  # noqa: E402


def test_plan_refuses_a_budget_beyond_a_week_of_table_time(capsys):
    with pytest.raises(ValueError, match=r"budget_min 1e\+09 min is 1.9e\+03 years of rate-table time per device; "
                                         r"the planner designs at most 10080 min \(7 days\)"):
        gj.plan("paper-qmg", None, budget_min=1e9)
    assert MAX_BUDGET_MIN == 7 * 24 * 60
    # the command says so, exit 2, before any fit
    assert main(["plan", table2_path(), "--budget-min", "1e9", "--quiet"]) == 2
    assert "1.9e+03 years of rate-table time" in capsys.readouterr().err


def _fit(status, chi2_red=(1.0,), p=(0.5,)):
    return types.SimpleNamespace(devices=tuple(f"d{i}" for i in range(len(status))), status=tuple(status),
                                 chi2_red=np.asarray(chi2_red), p_value=np.asarray(p))


def _design(rates, minutes=135.0):
    return types.SimpleNamespace(rates_dps=tuple(rates), minutes=minutes)


def test_the_plan_warns_of_a_rejected_model_a_design_blind_to_nonlinearity_and_a_long_design():
    fit = _fit(("ok", "model rejected"), chi2_red=(1.0, 4.4e5), p=(0.5, 0.0))
    w = _warnings(fit, _design((-200.0, 200.0), minutes=3000.0), 2)
    assert len(w) == 3
    assert w[0].startswith("the data reject the model this plan is made from on 1 of 2 device(s) (e.g. d1: "
                           "chi2_red 4.4e+05")
    assert "carry no nonlinearity information: a straight line through 2 rate(s) leaves no residual" in w[1]
    assert w[2] == "the scale-factor design takes 3000 min (2.08 days) of rate-table time per device, 4.17 days for " \
                   "the 2 devices on one table"
    # a model the data accept, a design with the intermediate rates, a day's budget: nothing to say
    assert _warnings(_fit(("ok",)), _design((-200.0, -50.0, 50.0, 200.0)), 1) == ()


def test_one_testability_rule():
    assert MIN_TYPICAL_CHI2 == 1.0
    assert not is_testable(0.0019) and not is_testable(math.nan) and is_testable(1.0) and is_testable(7.57)
    # a sweep separates two fingerprints only where what one leaves after the other is testable
    a = np.array([3.0, 0.0, 0.0])
    assert separates(a, np.array([0.0, 2.0, 0.0]))
    assert not separates(np.array([1e-3, 0.0]), np.array([0.0, 0.0]))


def _scored_fit():
    # 3 points x 2 runs: k_vf free (a line), damping_coupling barely seen (typical chi2 0.01), dac_inl well seen;
    # the residual lies along damping_coupling's column, far above the noise (its p-value underflows)
    rows = 12
    x = np.linspace(-1, 1, rows)
    damp = np.where(np.arange(rows) % 2 == 0, 1.0, -1.0) * 0.1 / math.sqrt(rows)  # |col|^2 = 0.01
    inl = x**3 * 10.0
    jac = np.stack([x, damp, inl], axis=1)[None]
    res = (1e4 * damp)[None]
    return types.SimpleNamespace(jacobian=jac, residual_vector=res, free=np.array([True, False, False]),
                                 names=("k_vf", "damping_coupling.c", "dac_inl.a"))


def test_diagnose_ranks_by_the_rule_whatever_the_p_value():
    scores = {c.effect: c for c in score_candidates(_scored_fit(), ["damping_coupling", "dac_inl"])}
    damp = scores["damping_coupling"]
    assert damp.p_value < 1e-100 and damp.typical_chi2 == pytest.approx(0.01, rel=0.05)
    assert not damp.testable  # typical chi2 0.01 < 1: not testable, as the plan says of it
    assert scores["dac_inl"].testable
    # the threshold is the diagnosis's min_typical_chi2
    loose = {c.effect: c for c in score_candidates(_scored_fit(), ["damping_coupling"], min_typical_chi2=1e-3)}
    assert loose["damping_coupling"].testable


def test_a_sweep_whose_rows_barely_differ_does_not_separate_two_effects():
    blocks = {"rate_table": types.SimpleNamespace(inputs=np.zeros((1, 1, 4))),
              "dac": types.SimpleNamespace(inputs=np.zeros((1, 1, 2)))}
    data = types.SimpleNamespace(sweeps=("rate_table", "dac"), blocks=blocks)
    a = np.array([[100.0, -50.0, 50.0, -100.0, 1e-3, 0.0]])
    b = np.array([[100.0, -50.0, 50.0, -100.0, 0.0, 0.0]])
    assert separating_sweep(a, b, data, 0.95) is None  # on the DAC rows a leaves chi2 1e-6
    a[0, 4] = 30.0
    assert separating_sweep(a, b, data, 0.95) == "dac"


def _score(effect, statistic, p, df=3, multiple=1.0):
    return types.SimpleNamespace(effect=effect, statistic=statistic, p_value=p, df=df, testable=True,
                                 implied_multiple=multiple)


def test_ranking_draws_the_statistic_on_a_log_axis_with_the_legend_off_the_bars():
    scores = [_score("dac_inl", 1.8e7, 0.0), _score("vref_drift", 4.8e5, 0.0), _score("thermal_drift", 30.0, 1e-5),
              _score("zro_tempco", 2.0, 0.6),
              types.SimpleNamespace(effect="duffing_drive", statistic=0.0, p_value=1.0, df=0, testable=False)]
    ax = gplot.ranking(scores, alpha=0.01)
    fig = ax.figure
    fig.canvas.draw()
    assert ax.get_xscale() == "log"
    widths = sorted(p.get_width() for p in ax.patches)
    assert widths == pytest.approx([2.0, 30.0, 4.8e5, 1.8e7])  # ranked by S, nothing capped
    legend = ax.get_legend().get_window_extent()
    assert legend.y1 <= ax.get_window_extent().y0 + 1.0  # below the axes: it covers no bar label
    plt.close(fig)


def _fake_diagnosis(nl, verdict="explained", remaining=()):
    fits = [types.SimpleNamespace(chi2_red_total=c) for c in (4.8e4, 0.96)]
    return types.SimpleNamespace(steps=(types.SimpleNamespace(effect="dac_inl"),), fits=fits, verdict=verdict,
                                 remaining=remaining), nl


def test_error_fall_labels_a_flat_nonlinearity_plainly_and_wraps_a_long_title(monkeypatch):
    d, nl = _fake_diagnosis([2.23866, 2.23866], verdict="partly explained")
    d.remaining = (types.SimpleNamespace(shape="a gain linear in the drive frequency (beyond the model's own) of "
                                               "every rate-table run", share=0.42),)
    values = iter(nl)
    monkeypatch.setattr(gplot, "nonlinearity_residual_ppm", lambda f: next(values))
    left, right = gplot.error_fall(d)
    left.figure.canvas.draw()
    assert right.get_yscale() == "linear"
    labels = [t.get_text() for t in right.get_yticklabels() if t.get_text()]
    assert labels and not any("times" in t or "^" in t for t in labels), labels
    lo, hi = right.get_ylim()
    assert lo <= 2.23866 <= hi and hi < 10
    title = left.get_title()
    assert "\n" in title and max(len(line) for line in title.splitlines()) <= 60
    assert left.get_yscale() == "log"  # 4.8e4 -> 0.96 spans decades
    plt.close(left.figure)


def test_fingerprints_leave_out_padding_and_tell_overlapping_lines_apart():
    # one device, one sweep of 2 runs x 3 points; the second run has 2 points (its third is padding)
    mask = np.array([[[True, True, True], [True, True, False]]])
    block = types.SimpleNamespace(inputs=np.zeros((1, 2, 3)), mask=mask)
    data = types.SimpleNamespace(sweeps=("rate_table",), blocks={"rate_table": block})
    fp = np.array([[1.0, 2.0, 3.0, 4.0, 5.0, 0.0]])
    baseline = types.SimpleNamespace(residual_vector=np.array([[1.1, 2.0, 2.9, 4.1, 5.0, 0.0]]), devices=("d0",),
                                     data=data)
    ranking = [types.SimpleNamespace(effect=e, testable=True, fingerprint=fp) for e in ("a", "b", "c")]
    axes = gplot.fingerprints(types.SimpleNamespace(baseline=baseline, ranking=ranking))
    ax = axes[0]
    points, *lines = ax.get_lines()[:4]
    assert list(points.get_xdata()) == [0, 1, 2, 3, 4]  # the padding point (5) is not drawn
    for line in lines:
        assert np.isnan(line.get_ydata()[5])
    styles = {(line.get_linestyle(), line.get_linewidth(), line.get_marker()) for line in lines}
    assert len(styles) == 3  # each candidate its own look: one on another stays visible
    assert "padding" not in axes[-1].get_xlabel()
    plt.close(ax.figure)


@pytest.mark.slow
def test_plan_of_the_dac_only_table2_follows_identifys_verdict_on_the_scale_factor(tmp_path):
    # seed 000's Table 2 has DAC points only: identify says SF NOT DETERMINED (exit 4); the plan says so too
    table = gj.read_table(table2_path())
    p = gj.plan("paper-qmg", table, max_repeats=1, progress=False)
    assert p.baseline.status == ("not determined",)
    s = p.scale_factor
    assert math.isnan(s.data_stderr[0]) and "cannot fix k_vf" in s.data_not_determined[0]
    text = p.summary()
    assert "on the data given: SF not determined by the data on 1 of 1 device(s), as identify rules" in text
    assert "stderr 2.967" not in text
    report = p.to_json()
    assert report["scale_factor"]["data_stderr"] == [None] and report["scale_factor"]["scale_factor"] == [None]
    # the +/-200 deg/s design says it measures no nonlinearity
    assert any("carry no nonlinearity information" in w for w in p.warnings)
    # the one rule: dac_inl leaves chi2 7.6 (testable, power 0.34: not yet detected); the rest nothing
    dac = p.candidate("dac_inl")
    assert dac.testable and not dac.detected and dac.recommended
    assert not p.candidate("agc_finite_gain").testable


def test_the_demos_default_folder_is_ignored_by_git():
    root = pathlib.Path(__file__).resolve().parent.parent
    assert "/gyrojax-demo/" in (root / ".gitignore").read_text().splitlines()


@pytest.mark.slow
def test_the_demo_says_where_it_writes_names_its_lot_and_explains_the_bandwidth(tmp_path, capsys, monkeypatch):
    from gyrojax._cli.demo_job import BANDWIDTH_NOTE, LOT_SOURCE

    monkeypatch.chdir(tmp_path)
    assert main(["demo", "--no-full", "--quiet"]) == 0  # the default folder, in the current one
    out = capsys.readouterr().out
    where = tmp_path / "gyrojax-demo"
    assert f"writing the demo's report, data and plots into {where}\n" in out
    assert f"paper reports 354.3 Hz (measured) / 349.5 Hz (simulated): {BANDWIDTH_NOTE}" in out
    assert "verdict: explained: dac_inl explains the data" in out
    report = (where / "diagnosis" / "diagnosis.md").read_text()
    assert f"Data: `{LOT_SOURCE}`" in report and str(tmp_path) not in report
