"""Malformed tables, generated: a valid small CSV mutated hundreds of ways (cells and rows dropped, duplicated,
shuffled; the file cut at random bytes; NaN, inf, empty, huge, tiny, negative, hex and text values; other
delimiters; bad encodings). Each read must be a `DataError` naming the file and a place, or a read whose every
value is what the text says - never another exception, never a silently wrong number."""

import codecs
import csv
import decimal
import io
import math
import random
import re

import numpy as np
import pytest

from gyrojax import DataError, read_table


N_CASES = 900
SEED = 20240611
COLUMNS = ["device", "run", "sweep", "input", "output", "output_sigma"]
ROWS = [["A", "0", "rate_table", "-10", "-137000.5", "0.5"],
        ["A", "0", "rate_table", "0", "12.0", ""],
        ["A", "0", "rate_table", "10", "137020.25", "0.5"],
        ["A", "1", "rate_table", "-10", "-137001.5", "0.25"],
        ["A", "1", "rate_table", "10", "137019.75", "0.25"],
        ["B", "0", "rate_table", "5", "6850.125", "1e-3"]]
VALUES = ["nan", "NaN", "inf", "-inf", "Infinity", "", " ", "1e400", "-1e400", "1e-400", "4.9e-324", "1e23", "-5",
          "-0", "0x1F", "1F", "29E345", "abc", "1_000", "  7  ", "+3", ".5", "5.", "1e5", "3.000", "2.5",
          "9" * 30, "1.0000000000000001", "\u0669", "\uff19", "7\xa0", '"4"', '"1,5"', "1,5", "'2'", "rate_table",
          "dac", "vcf_static", "A", "\x00", "true", "-", "e5", "1e", "1.2.3"]


def valid_text():
    return "\n".join(",".join(r) for r in [COLUMNS, *ROWS]) + "\n"


def mutate(rng: random.Random) -> bytes:
    lines = [line.split(",") for line in valid_text().splitlines()]
    for _ in range(rng.choice([1, 1, 1, 2, 3])):
        kind = rng.choice(["value", "value", "value", "drop_cell", "dup_cell", "shuffle_cells", "drop_row",
                           "dup_row", "shuffle_rows", "swap_cells", "header"])
        r = rng.randrange(1, len(lines)) if len(lines) > 1 else 0
        row = lines[r]
        if kind == "value" and row:
            numeric = [j for j in (1, 3, 4, 5) if j < len(row)]  # mostly numbers: there a misread would hide
            j = rng.choice(numeric) if numeric and rng.random() < 0.8 else rng.randrange(len(row))
            row[j] = rng.choice(VALUES)
        elif kind == "drop_cell" and row:
            del row[rng.randrange(len(row))]
        elif kind == "dup_cell" and row:
            j = rng.randrange(len(row))
            row.insert(j, row[j])
        elif kind == "shuffle_cells":
            rng.shuffle(row)
        elif kind == "drop_row" and len(lines) > 1:
            del lines[r]
        elif kind == "dup_row":
            lines.insert(r, list(row))
        elif kind == "shuffle_rows":
            body = lines[1:]
            rng.shuffle(body)
            lines = [lines[0], *body]
        elif kind == "swap_cells" and len(row) > 1:
            i, j = rng.sample(range(len(row)), 2)
            row[i], row[j] = row[j], row[i]
        elif kind == "header":
            lines[0][rng.randrange(len(lines[0]))] = rng.choice(["Output", "run ", "", "input", "extra", "device"])
    sep = rng.choice([","] * 18 + [";", "\t"])
    text = "\n".join(sep.join(r) for r in lines) + "\n"
    if rng.random() < 0.1:
        text = text.replace("\n", "\r\n")
    data = text.encode("utf-8")
    roll = rng.random()
    if roll < 0.15:
        data = data[:rng.randrange(len(data) + 1)]  # cut anywhere
    elif roll < 0.20:
        data = text.replace("A", "\xb5").encode(rng.choice(["latin-1", "utf-16", "cp1252"]), errors="replace")
    elif roll < 0.25:
        i = rng.randrange(len(data))
        data = data[:i] + bytes([rng.randrange(256)]) + data[i:]
    elif roll < 0.28:
        data = codecs.BOM_UTF8 + data
    return data


def expected_table(data: bytes):
    """What the text says, read independently: the rows as csv tokenises them, each value parsed exactly."""
    text = data.decode("utf-8-sig")
    rows = [r for r in csv.reader(io.StringIO(text, newline=""))]
    header = [h.strip() for h in rows[0]]
    body = [r for r in rows[1:] if any(c.strip() for c in r) or len(r) > 1]
    cols = {h: [r[j] for r in body] for j, h in enumerate(header)}
    out = {"device": [c.strip() for c in cols["device"]], "sweep": [c.strip() for c in cols["sweep"]],
           "run": [int(decimal.Decimal(c.strip())) for c in cols["run"]],
           "input": [float(c) for c in cols["input"]], "output": [float(c) for c in cols["output"]]}
    if "output_sigma" in cols:
        out["output_sigma"] = [float(c) if c.strip() else math.nan for c in cols["output_sigma"]]
    return out, text


PLACE = re.compile(r"data row \d+|line \d+|column '|header")


@pytest.mark.parametrize("block", range(6))
def test_malformed_tables_are_refused_or_read_exactly(tmp_path, block):
    rng = random.Random(SEED + block)
    outcomes = {"refused": 0, "read": 0}
    for case in range(N_CASES // 6):
        data = mutate(rng)
        path = tmp_path / f"case{block}_{case}.csv"
        path.write_bytes(data)
        try:
            table = read_table(path)
        except DataError as e:
            message = str(e)
            assert message.startswith(str(path)), (data, message)
            assert PLACE.search(message), (data, message)
            outcomes["refused"] += 1
            continue
        # Read: then it must be exactly what the text says, with nothing dropped.
        want, text = expected_table(data)
        assert text.rstrip(" \t").endswith(("\n", "\r")), data  # a file that may be cut short is never read
        assert len(table) == len(want["device"]), data
        for column, values in want.items():
            got = table[column].tolist()
            if column in ("input", "output", "output_sigma"):
                assert np.array_equal(np.asarray(got), np.asarray(values), equal_nan=True), (data, column, got)
                assert all(math.isfinite(v) for v in got) or column == "output_sigma", (data, column)
            else:
                assert got == values, (data, column, got)
        outcomes["read"] += 1
    assert outcomes["refused"] > 0 and outcomes["read"] > 0, outcomes  # the generator exercises both
