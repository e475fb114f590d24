"""The tidy data format: validation messages, exact file round trips, padded arrays, sample aggregation."""

import math
import os
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gyrojax import DataError, Table, read_table, write_table
from gyrojax._data import files as data_files, io as _io, validate as data_validate
from gyrojax.io import SweepArrays, aggregate_samples, decode_dac_word


HEADER = "device,run,sweep,input,output"
GOOD_ROWS = ["A,0,rate_table,-10,-137000.5", "A,0,rate_table,0,12.0", "A,0,rate_table,10,137020.5"]


def write_csv(tmp_path, lines, name="data.csv"):
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def cell(row, line, column):
    """The location text every cell error carries (data rows 1-based; line 1 is the header)."""
    return re.escape(f"data row {row} (line {line}), column '{column}'")


# ---------------------------------------------------------------------------------------------------------------
# Bad inputs: one test per case, each checking that the message names the file, row and column.


def test_good_file_reads(tmp_path):
    table = read_table(write_csv(tmp_path, [HEADER, *GOOD_ROWS]))
    assert len(table) == 3
    np.testing.assert_array_equal(table["input"], [-10.0, 0.0, 10.0])
    assert table["run"].dtype == np.int64
    assert table.locate(2, "output").endswith("data row 3 (line 4), column 'output'")


def test_missing_required_column(tmp_path):
    path = write_csv(tmp_path, ["device,run,sweep,input,Output_V", "A,0,rate_table,1,2"])
    with pytest.raises(DataError, match=re.escape(str(path)) + r".*header \(line 1\).*missing required column "
                       r"'output'"):
        read_table(path)


def test_unknown_sweep(tmp_path):
    path = write_csv(tmp_path, [HEADER, GOOD_ROWS[0], "A,0,rate-table,0,12.0"])
    with pytest.raises(DataError, match=cell(2, 3, "sweep") + r".*unknown sweep 'rate-table' \(did you mean "
                       r"'rate_table'\?\); expected one of rate_table, vcf_static, vcf_dynamic, dac"):
        read_table(path)


@pytest.mark.parametrize("bad", ["nan", "NaN", "inf", "-Infinity"])
def test_nan_or_inf(tmp_path, bad):
    path = write_csv(tmp_path, [HEADER, GOOD_ROWS[0], f"A,0,rate_table,0,{bad}", GOOD_ROWS[2]])
    with pytest.raises(DataError, match=re.escape(str(path)) + ": " + cell(2, 3, "output") + ".*not finite"):
        read_table(path)


@pytest.mark.parametrize("bad", ["12.3.4", "abc", "1_000", "0x10"])
def test_non_numeric_cell(tmp_path, bad):
    path = write_csv(tmp_path, [HEADER, GOOD_ROWS[0], GOOD_ROWS[1], f"A,0,rate_table,{bad},1.0"])
    with pytest.raises(DataError, match=cell(3, 4, "input") + ".*not .*number"):
        read_table(path)


def test_non_integer_run(tmp_path):
    path = write_csv(tmp_path, [HEADER, "A,1.5,rate_table,1,2"])
    with pytest.raises(DataError, match=cell(1, 2, "run") + ".*not an integer"):
        read_table(path)


def test_empty_required_cell(tmp_path):
    path = write_csv(tmp_path, [HEADER, "A,0,rate_table,1,", "A,0,rate_table,2,3"])
    with pytest.raises(DataError, match=cell(1, 2, "output") + ".*is empty"):
        read_table(path)


def test_duplicate_points(tmp_path):
    path = write_csv(tmp_path, [HEADER, *GOOD_ROWS, "B,0,rate_table,10,1.0", "A,0,rate_table,10.0,137021.0"])
    with pytest.raises(DataError, match=cell(5, 6, "input") + re.escape(
            ": duplicate point: data row 3 (line 4) has the same (device, run, sweep, input) = "
            "('A', 0, 'rate_table', 10) and time_s")):
        read_table(path)
    # The same input again within a run at another time (a plateau run) is another point; at the same time not.
    header = HEADER + ",time_s"
    rows = ["A,0,rate_table,10,137020.0,60", "A,0,rate_table,-10,-137020.0,180", "A,0,rate_table,10,137021.0,300"]
    assert len(read_table(write_csv(tmp_path, [header, *rows]))) == 3
    with pytest.raises(DataError, match="duplicate point: data row 1 .*and time_s"):
        read_table(write_csv(tmp_path, [header, *rows, "A,0,rate_table,10,137022.0,60"]))


def test_empty_file(tmp_path):
    path = tmp_path / "empty.csv"
    path.write_text("")
    with pytest.raises(DataError, match=re.escape(f"{path}: empty file: no header line")):
        read_table(path)


def test_header_only(tmp_path):
    path = write_csv(tmp_path, [HEADER])
    with pytest.raises(DataError, match=re.escape(f"{path}: empty: the header (line 1) is there but there are "
                                                  "no data rows")):
        read_table(path)


def test_wrong_field_count(tmp_path):
    path = write_csv(tmp_path, [HEADER, GOOD_ROWS[0], "A,0,rate_table,0"])
    with pytest.raises(DataError, match=re.escape("data row 2 (line 3) has 4 fields but the header has 5")):
        read_table(path)


def test_negative_sigma(tmp_path):
    path = write_csv(tmp_path, [HEADER + ",output_sigma", "A,0,rate_table,1,2,0.1", "A,0,rate_table,2,3,-0.1"])
    with pytest.raises(DataError, match=cell(2, 3, "output_sigma") + ".*negative"):
        read_table(path)


def test_rate_table_in_rad_per_s(tmp_path):
    rates_dps = [-200, -100, -50, -20, -10, -1, -0.1, 0, 0.1, 1, 10, 20, 50, 100, 200]
    rows = [f"A,0,rate_table,{repr(r * math.pi / 180)},{r * 13700.0}" for r in rates_dps]
    path = write_csv(tmp_path, [HEADER, *rows])
    with pytest.raises(DataError, match=re.escape("data row 1 (line 2) ... data row 15 (line 16) (15 rows), "
                                                  "column 'input': device 'A' run 0 rate_table inputs look like "
                                                  "rad/s") + r".*max \|input\| = 3\.49066.*input_dps = "
                                                  r"input_rad_s \* 180 / pi"):
        read_table(path)


@pytest.mark.parametrize("rates", [
    [-5, -2, -1, -0.5, 0.5, 1, 2, 5],  # a small-range deg/s table: max < 2 pi but not a converted grid
    [-200, -100, 0, 100, 200],  # ordinary
    [-3.0, 3.0],  # too few magnitudes to judge
    [0.5 * math.pi / 180, 0.2 * math.pi / 180],  # two converted magnitudes are enough
])
def test_rad_heuristic_cases(rates):
    x = np.asarray(rates, dtype=float)
    expected = len(np.unique(np.abs(x[x != 0]))) >= 2 and np.allclose(np.round(x * 1800 / math.pi),
                                                                       x * 1800 / math.pi, rtol=1e-12)
    assert data_validate.looks_like_rad_s(x) == expected


@pytest.mark.parametrize("word, message", [
    ("29G345", "the characters 'G' are not hex digits"),
    ("0x1234567", "has 7 hex digits; a 24-bit word has at most 6"),
    ("ABCDEF1", "has 7 hex digits"),
    ("12.5", "is not an integer"),
    ("43,033", "stray thousands separator"),
    ("9000000", "outside the 24-bit range"),
])
def test_malformed_dac_word(tmp_path, word, message):
    path = write_csv(tmp_path, [HEADER, "A,0,dac,0x10,0.1", f'A,0,dac,"{word}",0.2'])
    with pytest.raises(DataError, match=cell(2, 3, "input") + ".*" + re.escape(message)):
        read_table(path)


def test_ambiguous_bare_hex_and_digits(tmp_path):
    # Seed 000 prints 'A95' and '539' in the same column: 539 is hex there, but nothing in the cell says so.
    path = write_csv(tmp_path, [HEADER, "A,0,dac,A95,0.00163", "A,0,dac,539,0.0008217"])
    with pytest.raises(DataError, match=cell(2, 3, "input") + re.escape(": DAC word '539' is ambiguous")):
        read_table(path)


def test_unknown_suffix(tmp_path):
    with pytest.raises(ValueError, match=r"use \.csv or \.parquet"):
        read_table(tmp_path / "data.txt")
    table = read_table(write_csv(tmp_path, [HEADER, *GOOD_ROWS]))
    with pytest.raises(ValueError, match=r"'\.xlsx'; use \.csv or \.parquet"):
        write_table(table, tmp_path / "data.xlsx")


def test_parquet_nan_is_refused(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = tmp_path / "bad.parquet"
    pq.write_table(pa.table({"device": ["A", "A"], "run": [0, 0], "sweep": ["rate_table"] * 2,
                             "input": [1.0, 2.0], "output": [1.0, float("nan")]}), path)
    with pytest.raises(DataError, match=re.escape(f"{path}: data row 2, column 'output'") + ".*not finite"):
        read_table(path)


def test_parquet_null_in_required_column(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = tmp_path / "bad.parquet"
    pq.write_table(pa.table({"device": ["A", None], "run": [0, 0], "sweep": ["rate_table"] * 2,
                             "input": [1.0, 2.0], "output": [1.0, 2.0]}), path)
    with pytest.raises(DataError, match=re.escape("data row 2, column 'device'") + ".*is empty"):
        read_table(path)


def test_from_columns_validates():
    with pytest.raises(DataError, match=re.escape("<memory>: data row 2, column 'sweep': unknown sweep 'dc'")):
        Table.from_columns({"device": ["A", "A"], "run": [0, 0], "sweep": ["dac", "dc"], "input": [1, 2],
                            "output": [0.1, 0.2]})


def test_data_error_attributes(tmp_path):
    path = write_csv(tmp_path, [HEADER, GOOD_ROWS[0], "A,0,rate_table,0,oops"])
    with pytest.raises(DataError) as info:
        read_table(path)
    assert (info.value.source, info.value.row, info.value.column) == (str(path), 2, "output")
    assert isinstance(info.value, ValueError)


# ---------------------------------------------------------------------------------------------------------------
# DAC words.


@pytest.mark.parametrize("text, value", [
    ("29E345", 2745157), ("0xD61C74", -2745228), ("0XD61C74", -2745228), ("A95", 2709), ("539", 1337),
    ("800000", -(1 << 23)), ("7FFFFF", (1 << 23) - 1), ("FFFFFF", -1), ("FFFA81", -1407), ("0", 0),
])
def test_decode_dac_word(text, value):
    assert decode_dac_word(text) == value


def test_dac_inputs_hex_and_decimal(tmp_path):
    path = write_csv(tmp_path, [HEADER, "A,0,dac,0x29E345,1.637", "A,0,dac,-2745228,-1.637",
                                "A,0,dac,0xFFFA81,-0.000809", "A,0,dac,1337.0,0.0008217"])
    table = read_table(path)
    np.testing.assert_array_equal(table["input"], [2745157, -2745228, -1407, 1337])


# ---------------------------------------------------------------------------------------------------------------
# Round trips.


def full_table() -> Table:
    """Every optional column (some values not given), an unknown extra column, values that stress repr."""
    rng = np.random.default_rng(7)
    n = 7
    sigma = rng.uniform(0.1, 1.0, n)
    sigma[3] = np.nan  # not given
    return Table.from_columns({
        "device": ["dev-1", "dev-1", "dev-1", "dev 2", "dev 2", "dev 2", "dev 2"],
        "run": [0, 0, 0, 1, 1, 1, 1],
        "sweep": ["rate_table", "rate_table", "rate_table", "dac", "dac", "dac", "vcf_dynamic"],
        "input": [-0.1, 1.0 / 3.0, 200.0, "0xD61C74", "29E345", -7, 12.5],
        "output": rng.normal(size=n) * 1e4,
        "output_sigma": sigma,
        "n_samples": [12000, 12000, 11999, 1, 2, 3, np.nan],
        "phase_deg": [np.nan] * 6 + [-44.999999999999],
        "temperature_c": rng.uniform(20, 30, n),
        "drive_freq_hz": 4634.0 + rng.normal(size=n) * 1e-3,
        "rate_dps": [np.nan, np.nan, np.nan, 200.0, -200.0, 0.1, np.nan],
        "operator": ["ann", "ann", "bob, jr.", 'quote "q"', "", "x", "y"],
    }, source="full")


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_round_trip_exact(tmp_path, suffix):
    table = full_table()
    path = tmp_path / f"lot{suffix}"
    write_table(table, path)
    back = read_table(path)
    assert back.column_names == table.column_names
    for name in table.column_names:
        a, b = table[name], back[name]
        if a.dtype.kind == "f":
            assert b.dtype == np.float64
            np.testing.assert_array_equal(a, b)  # exact, NaN where not given
            assert np.array_equal(np.isnan(a), np.isnan(b))
        else:
            assert a.tolist() == b.tolist(), name
    assert back.equals(table)
    # And once more: file -> table -> file is byte-identical for CSV.
    if suffix == ".csv":
        again = tmp_path / "again.csv"
        write_table(back, again)
        assert again.read_bytes() == path.read_bytes()


def test_csv_text_is_exact_and_readable(tmp_path):
    path = tmp_path / "t.csv"
    write_table(full_table(), path)
    lines = path.read_text().splitlines()
    assert lines[0] == ("device,run,sweep,input,output,output_sigma,n_samples,phase_deg,temperature_c,"
                        "drive_freq_hz,rate_dps,operator")
    assert lines[2].split(",")[3] == "0.3333333333333333"  # repr: shortest exact text
    assert lines[4].split(",")[3] == "-2745228"  # DAC words as integers
    assert lines[4].split(",")[5] == ""  # sigma not given -> empty


def test_write_is_atomic(tmp_path, monkeypatch):
    path = tmp_path / "lot.csv"
    write_table(full_table(), path)
    before = path.read_bytes()

    def broken(table, f):
        f.write("device,run,sweep,input,output\nhalf-written")
        raise RuntimeError("disk full")

    monkeypatch.setattr(data_files, "_write_csv", broken)
    with pytest.raises(RuntimeError, match="disk full"):
        write_table(full_table(), path)
    assert path.read_bytes() == before
    assert sorted(os.listdir(tmp_path)) == ["lot.csv"]  # no temporary file left behind


# ---------------------------------------------------------------------------------------------------------------
# Padded arrays.


def ragged_table() -> Table:
    rows = []
    # Device B has 1 run of 2 points, device A 2 runs of 3 and 4 points; a dac row in between is not carried.
    for dev, run, xs in [("A", 0, [-1.0, 0.0, 1.0]), ("A", 2, [-2.0, -1.0, 1.0, 2.0]), ("B", 5, [3.0, 4.0])]:
        for x in xs:
            rows.append({"device": dev, "run": run, "sweep": "rate_table", "input": x, "output": 10 * x + run,
                         "output_sigma": 0.5 + abs(x), "temperature_c": 25.0 + x if x != 0 else None})
    rows.insert(3, {"device": "A", "run": 0, "sweep": "dac", "input": "0x10", "output": 1.0})
    return Table.from_records(rows)


def test_to_arrays_layout():
    arrays = ragged_table().to_arrays("rate_table")
    assert isinstance(arrays, SweepArrays)
    assert arrays.inputs.shape == (2, 2, 4)
    assert arrays.devices == ("A", "B") and arrays.runs == ((0, 2), (5,))
    np.testing.assert_array_equal(arrays.mask.sum(axis=-1), [[3, 4], [2, 0]])
    np.testing.assert_array_equal(arrays.inputs[0, 1], [-2, -1, 1, 2])
    np.testing.assert_array_equal(arrays.outputs[1, 0], [30 + 5, 40 + 5, 0, 0])  # padded with 0
    np.testing.assert_array_equal(arrays.sigmas[1, 1], [1, 1, 1, 1])  # padding sigma 1
    assert arrays.inputs.dtype == jnp.float64
    assert arrays.aux == {}  # temperature_c is the field temperatures
    assert np.isnan(arrays.temperatures[0, 0, 1])  # not given stays NaN
    np.testing.assert_array_equal(arrays.temperatures[0, 1], [23.0, 24.0, 26.0, 27.0])
    np.testing.assert_array_equal(arrays.temperatures[1], [[28.0, 29.0, 25.0, 25.0], [25.0] * 4])  # padding 25
    assert np.all(np.isnan(arrays.times)) and np.all(np.isnan(arrays.drive_freqs))  # not recorded
    np.testing.assert_array_equal(arrays.order[0], [[0, 1, 2, 0], [0, 1, 2, 3]])  # file order, padding 0


def test_arrays_round_trip_exact():
    table = ragged_table()
    arrays = table.to_arrays("rate_table")
    back = Table.from_arrays(arrays)
    expected = table.select([i for i in range(len(table)) if table["sweep"][i] == "rate_table"])
    assert back.column_names == expected.column_names
    assert back.equals(expected)
    assert Table.from_arrays(back.to_arrays("rate_table")).equals(back)


def test_arrays_vmap():
    arrays = ragged_table().to_arrays("rate_table")

    def masked_mean(a: SweepArrays):
        w = jnp.where(a.mask, 1.0, 0.0)
        return jnp.sum(w * a.outputs, axis=-1) / jnp.maximum(jnp.sum(w, axis=-1), 1.0)

    out = jax.vmap(masked_mean)(arrays)  # vmap over the device axis of every array field
    np.testing.assert_allclose(out, [[0.0, 2.0], [40.0, 0.0]])


def test_fit_data_holds_sweep_arrays_aligned_on_the_lot():
    """A fit's data is one SweepArrays per sweep kind on the lot's device axis: a device a sweep lacks has
    padding only; `unlabelled()` keeps the arrays and drops the labels."""
    from gyrojax._model.fitdata import fit_data

    rows = [{"device": d, "run": r, "sweep": "rate_table", "input": x, "output": 2 * x, "output_sigma": 0.1}
            for d, r, xs in (("A", 0, [-1.0, 0.0, 1.0]), ("B", 5, [3.0, 4.0])) for x in xs]
    rows += [{"device": "B", "run": 1, "sweep": "vcf_static", "input": x, "output": x, "output_sigma": 0.2,
              "time_s": t} for x, t in ((0.5, 20.0), (1.0, 10.0))]
    data = fit_data(Table.from_records(rows))
    assert data.devices == ("A", "B") and data.sweeps == ("rate_table", "vcf_static") and data.weighted
    vcf = data.blocks["vcf_static"]
    assert isinstance(vcf, SweepArrays) and vcf.devices == ("A", "B") and vcf.aux == {}
    assert data.run_ids("vcf_static") == ((), (1,)) and data.run_ids("rate_table") == ((0,), (5,))
    np.testing.assert_array_equal(vcf.mask, [[[False, False]], [[True, True]]])
    np.testing.assert_array_equal(vcf.inputs[1, 0], [0.5, 1.0])
    np.testing.assert_array_equal(vcf.order[1, 0], [1, 0])  # by time_s, not file order
    np.testing.assert_array_equal(vcf.sigmas[0], [[1.0, 1.0]])  # padding
    np.testing.assert_array_equal(vcf.temperatures[0], [[25.0, 25.0]])  # padding
    assert np.all(np.isnan(vcf.temperatures[1])) and np.all(np.isnan(vcf.times[0]))  # not recorded; padding
    back = Table.from_arrays(vcf)
    np.testing.assert_array_equal(back["time_s"], [20.0, 10.0])
    bare = data.unlabelled()
    assert bare.devices is None and bare.weighted is None and bare.source is None
    assert bare.blocks["vcf_static"].runs is None
    for a, b in zip(jax.tree.leaves(data), jax.tree.leaves(bare)):
        assert a is b
    unweighted = fit_data(Table.from_records([{k: v for k, v in r.items() if k != "output_sigma"} for r in rows]))
    assert not unweighted.weighted
    np.testing.assert_array_equal(unweighted.blocks["rate_table"].sigmas, np.ones((2, 1, 3)))


def test_to_arrays_missing_sweep():
    with pytest.raises(DataError, match="no rows with sweep 'vcf_static'; the table has dac, rate_table"):
        ragged_table().to_arrays("vcf_static")


# ---------------------------------------------------------------------------------------------------------------
# Aggregation of raw samples.


def ar1(rng, n, phi, sigma):
    e = rng.normal(scale=sigma * math.sqrt(1 - phi**2), size=n)
    x = np.empty(n)
    x[0] = rng.normal(scale=sigma)
    for i in range(1, n):
        x[i] = phi * x[i - 1] + e[i]
    return x


def test_aggregate_white_noise():
    rng = np.random.default_rng(1)
    samples = 5.0 + rng.normal(scale=2.0, size=20000)
    rec = aggregate_samples("A", 0, "rate_table", 10.0, samples, sample_rate_hz=100.0)
    assert rec["n_samples"] == 20000
    assert rec["output"] == pytest.approx(np.mean(samples), abs=0)
    # Batch means agree with sigma/sqrt(N) for white noise, to their own scatter (1/sqrt(2*19) = 16%).
    assert rec["output_sigma"] == pytest.approx(2.0 / math.sqrt(20000), rel=0.4)


def test_aggregate_correlated_noise_is_not_underestimated():
    # AR(1), phi = 0.95: the naive sigma/sqrt(N) is sqrt((1-phi)/(1+phi)) = 1/6.2 of the truth.
    phi, sigma, n = 0.95, 1.0, 40000
    truth = sigma * math.sqrt((1 + phi) / (1 - phi) / n)
    ratios, naive = [], []
    for seed in range(5):
        x = ar1(np.random.default_rng(seed), n, phi, sigma)
        rec = aggregate_samples("A", 0, "vcf_static", 0.5, x, sample_rate_hz=1000.0)
        ratios.append(rec["output_sigma"] / truth)
        naive.append(np.std(x, ddof=1) / math.sqrt(n) / truth)
    assert 0.75 < np.mean(ratios) < 1.25
    assert max(naive) < 0.2


def test_aggregate_discard_and_dac_word():
    samples = np.concatenate([np.full(150, 99.0), np.arange(1000.0)])  # 1.5 s of settling at 100 Hz
    rec = aggregate_samples("A", 3, "dac", "0xD61C74", samples, sample_rate_hz=100.0, discard_s=1.5)
    assert rec["n_samples"] == 1000 and rec["output"] == pytest.approx(499.5)
    assert rec["input"] == -2745228
    table = Table.from_records([rec])
    assert table["n_samples"][0] == 1000.0


def test_aggregate_refuses_too_few_and_nan():
    with pytest.raises(DataError, match=re.escape("aggregate_samples(device='A', run=0, sweep='rate_table', "
                                                  "input=1.0): 30 samples left after discarding 10")):
        aggregate_samples("A", 0, "rate_table", 1.0, np.zeros(40), sample_rate_hz=10.0, discard_s=1.0)
    with pytest.raises(DataError, match=r"sample 3 \(0-based\) is nan"):
        aggregate_samples("A", 0, "rate_table", 1.0, [0.0, 1.0, 2.0, np.nan] * 20, sample_rate_hz=10.0)
    with pytest.raises(DataError, match="unknown sweep 'rate'"):
        aggregate_samples("A", 0, "rate", 1.0, np.zeros(100), sample_rate_hz=10.0)


def test_not_utf8(tmp_path):
    path = tmp_path / "latin1.csv"
    path.write_bytes((HEADER + "\nA\xb5,0,rate_table,1,2\n").encode("latin-1"))
    with pytest.raises(DataError, match="not UTF-8 text"):
        read_table(path)


def test_hex_word_in_a_rate_table_row(tmp_path):
    path = write_csv(tmp_path, [HEADER, "A,0,rate_table,29E345,1.0"])
    with pytest.raises(DataError, match=cell(1, 2, "input") + ".*overflows float64.*belongs in a dac sweep"):
        read_table(path)


def test_written_file_is_readable_by_others(tmp_path):
    path = tmp_path / "lot.parquet"
    write_table(full_table(), path)
    assert path.stat().st_mode & 0o777 == 0o666 & ~_io._UMASK


# ---------------------------------------------------------------------------------------------------------------
# Files that used to be misread or crash (the "never a silently wrong number" cases).


@pytest.mark.parametrize("run, what", [
    ("1e23", "is outside the range of a run id"),
    ("99999999999999999999", "is outside the range of a run id"),
    ("-2147483649", "is outside the range of a run id"),
    ("1e999999999", "is outside the range of a run id"),
    ("1.0000000000000001", "is not an integer"),
    ("2.5e0", "is not an integer"),
])
def test_run_must_be_a_small_integer(tmp_path, run, what):
    path = write_csv(tmp_path, [HEADER, GOOD_ROWS[0], f"A,{run},rate_table,0,12.0"])
    with pytest.raises(DataError, match=re.escape(str(path)) + ": " + cell(2, 3, "run") + ": "
                       + re.escape(f"{run!r} {what}; expected an integer in [-2147483648, 2147483647]")):
        read_table(path)


@pytest.mark.parametrize("run, value", [("3", 3), ("3.000", 3), ("1e3", 1000), ("2147483647", 2147483647),
                                        ("-2147483648", -2147483648)])
def test_integer_runs_in_range_read_exactly(tmp_path, run, value):
    table = read_table(write_csv(tmp_path, [HEADER, f"A,{run},rate_table,0,12.0"]))
    assert table["run"].tolist() == [value]


def test_underflow_is_refused(tmp_path):
    path = write_csv(tmp_path, [HEADER, "A,0,rate_table,0,1e-400"])
    with pytest.raises(DataError, match=cell(1, 2, "output") + ".*'1e-400' underflows float64 to 0"):
        read_table(path)
    assert read_table(write_csv(tmp_path, [HEADER, "A,0,rate_table,0,0e-400"], "zero.csv"))["output"][0] == 0.0


@pytest.mark.parametrize("sep, what", [(";", "semicolon"), ("\t", "tab")])
def test_other_separators_are_named(tmp_path, sep, what):
    path = write_csv(tmp_path, [HEADER.replace(",", sep), *(r.replace(",", sep) for r in GOOD_ROWS)])
    shown = repr(HEADER.replace(",", sep))
    with pytest.raises(DataError, match=re.escape(f"{path}: the header (line 1) has one column {shown}: the file "
                                                  f"looks {what}-separated; gyrojax reads comma-separated CSV")):
        read_table(path)


def test_directory_is_refused(tmp_path):
    folder = tmp_path / "lot.csv"
    folder.mkdir()
    with pytest.raises(DataError, match=re.escape(f"{folder} is a directory; give a .csv or .parquet file.")):
        read_table(folder)


def test_file_cut_inside_its_last_number_is_refused(tmp_path):
    rows = [f"A,0,rate_table,{x},{x * 13771.0 + 1.5}" for x in (-10, -5, 0, 5, 10)]
    whole = "\n".join([HEADER, *rows]) + "\n"
    path = tmp_path / "cut.csv"
    path.write_text(whole[:-6])  # '137711.5' -> '13'
    with pytest.raises(DataError, match=re.escape(f"{path}: data row 5 (line 6) does not end with a newline, so the "
                                                  "file may have been cut short inside it") + ".*add a final newline"):
        read_table(path)
    path.write_text(whole[:-1])  # complete, but without the final newline: refused the same way
    with pytest.raises(DataError, match="data row 5 \\(line 6\\) does not end with a newline"):
        read_table(path)
    path.write_text(HEADER)
    with pytest.raises(DataError, match=re.escape("the header (line 1) does not end with a newline")):
        read_table(path)
    path.write_text(whole + "   ")  # a blank last line holds no data: fine
    assert len(read_table(path)) == 5
    path.write_text(whole.replace("\n", "\r\n"))
    assert read_table(path)["output"][-1] == 137711.5


def test_not_utf8_names_the_line(tmp_path):
    path = tmp_path / "latin1.csv"
    path.write_bytes((HEADER + "\nA,0,rate_table,1,2\nA\xb5,0,rate_table,2,3\n").encode("latin-1"))
    with pytest.raises(DataError, match=re.escape(f"{path}: line 3: not UTF-8 text (byte 50: invalid start byte)")):
        read_table(path)


def test_written_files_end_with_a_newline_and_read_back(tmp_path):
    path = tmp_path / "t.csv"
    write_table(full_table(), path)
    assert path.read_bytes().endswith(b"\n")
    assert read_table(path).equals(full_table())


def test_every_csv_shipped_reads_back():
    from importlib import resources

    shipped = [p for p in resources.files("gyrojax").joinpath("data").iterdir() if p.name.endswith(".csv")]
    assert shipped
    for p in shipped:
        assert p.read_bytes().endswith(b"\n"), p.name
        assert len(read_table(str(p))) > 0


def test_write_table_through_a_symlink_keeps_mode_and_link(tmp_path):
    target = tmp_path / "real.csv"
    write_table(full_table(), target)
    target.chmod(0o640)
    link = tmp_path / "link.csv"
    link.symlink_to("real.csv")
    write_table(full_table().select([0, 1, 2]), link)
    assert link.is_symlink()
    assert len(read_table(target)) == 3
    assert target.stat().st_mode & 0o777 == 0o640
