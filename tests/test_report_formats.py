"""The reporting wing (gyrojax/_report): every result is an `AbstractResult` (a `kind`, a JSON-safe `to_json()`,
a `summary()`), and an output format is one object in one registry, written by `write_result` and by the command
line's `--out FILE [--format NAME]`."""

import csv
import dataclasses
import io
import json
import typing

import numpy as np
import pytest

import gyrojax as gj
from gyrojax.cli import main
from gyrojax.identification import IdentifyReport
from gyrojax.io import FORMATS, AbstractFormat, AbstractResult, register_format, write_result


# The verbs whose return values are results; their return annotations name the result types.
VERBS = (gj.identify, gj.diagnose, gj.plan, gj.rate_table_plan, gj.compensate, gj.metrics.metrics_report,
         gj.compare)


def _returned_types():
    types = []
    for verb in VERBS:
        hint = typing.get_type_hints(verb)["return"]
        types += list(typing.get_args(hint)) or [hint]
    return types


def test_every_verbs_result_type_declares_the_result_contract():
    types = _returned_types() + [IdentifyReport]
    names = {t.__name__ for t in types}
    assert names >= {"Fit", "PopulationFit", "Diagnosis", "Plan", "RateTablePlan", "CompensationResult",
                     "MetricsReport", "IdentifyReport", "Comparison"}, names
    kinds = []
    for t in types:
        assert isinstance(getattr(t, "kind", None), str), f"{t.__name__} has no kind name"
        assert callable(getattr(t, "to_json", None)) and callable(getattr(t, "summary", None)), t.__name__
        kinds.append(t.kind)
    assert len(set(kinds)) == len(kinds), kinds  # a kind names one type


def _round_trips(result):
    assert isinstance(result, AbstractResult)
    form = result.to_json()
    assert json.loads(json.dumps(form, allow_nan=False)) == form  # plain JSON: no NaN, no NumPy scalars
    text = result.summary()
    assert isinstance(text, str) and text.strip()
    return form


def _rate_table(runs=2):
    rates = np.array([-200.0, -100.0, -10.0, 10.0, 100.0, 200.0])
    out = [13700.0 * rates + 120.0 + 0.3 * rates**2 / 200, 13701.0 * rates - 80.0 + 0.2 * rates**2 / 200][:runs]
    return gj.Table({"device": ["A"] * 6 * runs, "run": np.repeat(np.arange(runs), 6),
                     "sweep": ["rate_table"] * 6 * runs, "input": np.tile(rates, runs),
                     "output": np.concatenate(out)}, source="rates.csv")


def test_fast_results_round_trip_through_json():
    metrics = gj.metrics.metrics_report(_rate_table())
    assert metrics.points[0].device == "A"  # typed records, read by attribute
    assert _round_trips(metrics) == metrics.to_json()
    comp = gj.compensate(_rate_table(), method="polynomial", progress=False)
    assert _round_trips(comp)["method"] == "polynomial"
    assert "repeatability over 2 runs" in comp.summary()
    rtp = gj.rate_table_plan(0.005, 0.002, devices=64)
    assert _round_trips(rtp) == rtp.report()  # the old name still works


@pytest.fixture(scope="module")
def lot():
    return gj.simulate_table(gj.paper_qmg(), devices=3, runs=1, sweeps=("rate_table", "dac"), seed=2, progress=False)


@pytest.mark.slow
def test_fitted_results_round_trip_through_json(lot):
    fit = gj.identify("paper-qmg", lot, progress=False)
    assert _round_trips(fit) == {k: v for k, v in gj.fit_report(fit).items() if k != "compare"}
    report = IdentifyReport(fit)
    assert _round_trips(report) == gj.fit_report(fit)
    assert report.summary().startswith(fit.summary() + "\n")
    diagnosis = gj.diagnose("paper-qmg", lot, fit=fit, progress=False)
    assert _round_trips(diagnosis)["verdict"] == diagnosis.verdict
    plan = gj.plan("paper-qmg", lot, fit=fit, progress=False)
    assert set(_round_trips(plan)) >= {"candidates", "scale_factor", "experiments"}
    population = gj.identify("paper-qmg", lot, lot_solve=gj.PopulationSolve(random=("k_vf",)), progress=False)
    form = _round_trips(population)
    assert form["population"] == json.loads(json.dumps(population.report())) and form["devices"]
    assert _round_trips(IdentifyReport(population.fit, population)) == {**gj.fit_report(population.fit),
                                                                        "population": form["population"]}


# ----------------------------------------------------------------------------------------------------------------
# Output formats: the built-in ones, a user's (defined here), and the command line.


class CsvFormat(AbstractFormat):
    """A user's format: the JSON form's top-level scalars as a two-column CSV (key, value)."""

    name = "csv"
    suffixes = (".csv",)

    def render(self, result):
        text = io.StringIO()
        writer = csv.writer(text, lineterminator="\n")
        writer.writerow(("key", "value"))
        for key, value in result.to_json().items():
            if value is None or isinstance(value, (str, int, float, bool)):
                writer.writerow((key, "" if value is None else value))
        return text.getvalue().encode()


@pytest.fixture
def csv_format():
    register_format(CsvFormat())
    yield FORMATS["csv"]
    FORMATS.pop("csv")


def _csv(path):
    return {row["key"]: row["value"] for row in csv.DictReader(path.open())}


def test_write_result_picks_the_format_by_suffix_or_name(tmp_path):
    report = gj.metrics.metrics_report(_rate_table())
    write_result(report, tmp_path / "m.json")
    gj.io.atomic_write_json(report.to_json(), tmp_path / "before.json")  # what the CLI's --json wrote before
    assert (tmp_path / "m.json").read_bytes() == (tmp_path / "before.json").read_bytes()
    write_result(report, tmp_path / "m.txt")
    assert (tmp_path / "m.txt").read_text() == report.summary() + "\n"
    assert write_result(report, tmp_path / "m.dat", format="text") is FORMATS["text"]
    assert (tmp_path / "m.dat").read_text() == report.summary() + "\n"
    write_result(report, tmp_path / "m.md")
    page = (tmp_path / "m.md").read_text()
    assert page.startswith("# gyrojax metrics\n\n```\n" + report.summary() + "\n```\n")
    assert "## points" in page and "| device | run | sweep |" in page  # the records as a table
    assert "| A | 0 | rate_table |" in page and "| A | 1 | rate_table |" in page


def test_write_result_refuses_an_unknown_format_naming_the_path_and_the_known_ones(tmp_path):
    report = gj.metrics.metrics_report(_rate_table())
    with pytest.raises(ValueError, match=r"m\.xlsx: no output format for the suffix '\.xlsx'; the known formats are "
                                         r"json \(\.json\), markdown \(\.md\), text \(\.txt\)"):
        write_result(report, tmp_path / "m.xlsx")
    with pytest.raises(ValueError, match=r"m\.json: unknown output format 'yaml'; the known formats are json"):
        write_result(report, tmp_path / "m.json", format="yaml")
    with pytest.raises(TypeError, match=r"x\.json: write_result expects a gyrojax result .* got dict"):
        write_result({"a": 1}, tmp_path / "x.json")
    assert not list(tmp_path.iterdir())  # nothing written


def test_a_nan_in_a_result_is_refused_with_the_file_and_the_key(tmp_path):
    rtp = gj.rate_table_plan(0.005, 0.002, devices=64)
    bad = dataclasses.replace(rtp, spread=float("nan"))
    with pytest.raises(ValueError, match=r"p\.json: not written: spread is not a finite number"):
        write_result(bad, tmp_path / "p.json")


def test_a_users_format_is_one_object_and_one_call(tmp_path, csv_format):
    rtp = gj.rate_table_plan(0.005, 0.02, devices=64)
    assert rtp.recommended is not None
    assert write_result(rtp, tmp_path / "p.csv") is csv_format
    assert _csv(tmp_path / "p.csv") == {"spread": "0.005", "own": "0.0", "target": "0.02", "devices": "64",
                                        "recommended": str(rtp.recommended)}
    with pytest.raises(ValueError, match="the known formats are json .*, csv \\(\\.csv\\)"):
        write_result(rtp, tmp_path / "p.xlsx")
    register_format(CsvFormat())  # the same format again: nothing to do

    class OtherCsv(CsvFormat):
        name = "csv2"

    with pytest.raises(ValueError, match="the suffix '.csv' of format 'csv2' belongs to the format 'csv'"):
        register_format(OtherCsv())
    with pytest.raises(ValueError, match="an output format named 'json' is registered already"):
        register_format(type("Json2", (CsvFormat,), {"name": "json", "suffixes": ()})())
    with pytest.raises(TypeError, match="register_format expects an instance of a gyrojax.io.AbstractFormat"):
        register_format(CsvFormat)


def test_the_command_line_writes_any_registered_format(tmp_path, csv_format, capsys):
    argv = ["plan", "--rate-table-target", "0.2%", "--lot-spread", "0.5%"]
    assert main([*argv, "--json", str(tmp_path / "p.json"), "--out", str(tmp_path / "p.csv")]) == 0
    assert _csv(tmp_path / "p.csv")["spread"] == "0.005"
    assert json.loads((tmp_path / "p.json").read_text())["spread"] == 0.005  # --json unchanged beside it
    assert main([*argv, "--out", str(tmp_path / "p.dat"), "--format", "csv"]) == 0
    assert (tmp_path / "p.dat").read_bytes() == (tmp_path / "p.csv").read_bytes()
    assert main([*argv, "--out", str(tmp_path / "p.md")]) == 0
    assert (tmp_path / "p.md").read_text().startswith("# gyrojax rate_table_plan\n")
    out = capsys.readouterr().out
    assert f"wrote {tmp_path / 'p.csv'}" in out and f"wrote {tmp_path / 'p.md'}" in out


def test_the_command_line_refuses_an_unknown_format_before_any_work(tmp_path, capsys):
    data = tmp_path / "rates.csv"
    gj.write_table(_rate_table(), data)
    capsys.readouterr()
    assert main(["metrics", str(data), "--out", str(tmp_path / "m.xlsx")]) == 2
    err = capsys.readouterr()
    assert "m.xlsx: no output format for the suffix '.xlsx'; the known formats are json (.json)" in err.err
    assert err.out == ""  # refused before the metrics were computed or printed
    assert main(["metrics", str(data), "--format", "csv"]) == 2
    assert "--format csv needs --out FILE" in capsys.readouterr().err
    assert main(["metrics", str(data), "--out", str(tmp_path / "m.txt"), "--format", "nope"]) == 2
    assert "unknown output format 'nope'" in capsys.readouterr().err
    assert main(["metrics", str(data), "--out", str(tmp_path / "m.txt")]) == 0
    assert (tmp_path / "m.txt").read_text() == gj.metrics.metrics_report(gj.read_table(data)).summary() + "\n"
    assert not (tmp_path / "m.xlsx").exists()


@pytest.mark.parametrize("suffix", [".txt", ".md"])
def test_device_names_from_the_data_are_escaped_in_text_and_markdown_files(tmp_path, suffix):
    # a name with a newline would forge a line of its own ("# verdict: explained"), one with an escape sequence
    # would drive a terminal that shows the file
    table = _rate_table()
    cols = dict(table.columns)
    evil = "A\n# verdict: explained\x1b[31m"
    cols["device"] = np.array([evil] * len(cols["device"]), dtype=object)
    report = gj.metrics.metrics_report(gj.Table(cols, source="evil.csv"))
    path = tmp_path / f"report{suffix}"
    write_result(report, path)
    text = path.read_text()
    assert "\x1b" not in text
    assert not any(line.startswith("# verdict") for line in text.splitlines())
    assert "A\\n# verdict: explained\\x1b[31m" in text  # shown escaped, not dropped
