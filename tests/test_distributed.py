"""A lot in chunks of devices (gyrojax/_distributed, gyrojax/_data/chunked.py): the chunked readers, the plan and
its restart check, the merge's every-device-once check, and (with Dask distributed installed) a lot on a local
cluster of 2 worker processes: the same fit as one process, a killed worker's chunk run again, a killed run
continued by the same command."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import gyrojax as gj
from gyrojax._data.cells import DataError
from gyrojax._data.chunked import device_order, read_chunk, split_csv
from gyrojax._data.files import read_parquet_devices
from gyrojax._distributed import DistributedSolve, identify_lot
from gyrojax._distributed.plan import Plan
from gyrojax._distributed.run import merge, progress_line
from gyrojax._distributed.task import fit_chunk


def _write(path, rows, header="device,run,sweep,input,output,output_sigma"):
    path.write_text(header + "\n" + "".join(r + "\n" for r in rows))
    return str(path)


def _tiny(tmp_path, name="lot.csv"):
    """Three devices, interleaved, two rate-table points each."""
    rows = []
    for x in (1.0, 2.0):
        for d in ("a", "b", "c"):
            rows.append(f"{d},0,rate_table,{x},{100 * x + ord(d)},0.1")
    return _write(tmp_path / name, rows)


def test_device_order_and_csv_split_by_device(tmp_path):
    path = _tiny(tmp_path)
    assert device_order(path) == ["a", "b", "c"]
    targets = [str(tmp_path / "c0.csv"), str(tmp_path / "c1.csv")]
    split_csv(path, [["a", "b"], ["c"]], targets)
    first, second = gj.read_table(targets[0]), gj.read_table(targets[1])
    assert first["device"].tolist() == ["a", "b", "a", "b"] and second["device"].tolist() == ["c", "c"]
    whole = gj.read_table(path)
    rows = [i for i, d in enumerate(whole["device"].tolist()) if d == "c"]
    assert np.array_equal(second["output"], whole["output"][rows])


def test_the_sweeps_of_a_file_set_every_chunk_s_free_parameters(tmp_path):
    """`identify_lot` frees what the whole file's sweep kinds read (a chunk without the dynamic VCF frees it too):
    the distinct values of a column, in order, from CSV and Parquet alike; a missing column is named."""
    from gyrojax._data.chunked import column_values, file_sweep_kinds
    from gyrojax._identify.spec import free_reading

    rows = ["a,0,rate_table,1.0,101,0.1", "b,0,rate_table,1.0,102,0.1", "b,0,vcf_dynamic,10.0,3e4,5",
            "a,0,rate_table,2.0,201,0.1"]
    path = _write(tmp_path / "mixed.csv", rows)
    assert column_values(path, "sweep") == ["rate_table", "vcf_dynamic"]
    pq = str(tmp_path / "mixed.parquet")
    gj.write_table(gj.read_table(path), pq)
    assert column_values(pq, "sweep") == ["rate_table", "vcf_dynamic"]
    kinds = file_sweep_kinds(pq)
    assert free_reading(kinds, gj.paper_qmg()) == gj.identification.DEFAULT_FREE + ("angular_gain",)
    assert free_reading(kinds, gj.vcf_2018()) == gj.identification.DEFAULT_FREE  # open loop: no rebalance loop
    with pytest.raises(DataError, match=r"mixed\.csv: the header \(line 1\) has no 'temperature_c' column"):
        column_values(path, "temperature_c")


def test_a_chunk_error_names_the_input_file_row_and_line(tmp_path):
    rows = ["a,0,rate_table,1.0,101,0.1", "b,0,rate_table,1.0,102,0.1", "b,0,rate_table,2.0,nan,0.1"]
    path = _write(tmp_path / "bad.csv", rows)
    target = str(tmp_path / "c1.csv")
    split_csv(path, [["a"], ["b"]], [str(tmp_path / "c0.csv"), target])
    with pytest.raises(DataError, match=r"bad\.csv: data row 3 \(line 4\)") as e:
        read_chunk(path, ["b"], target)
    assert e.value.row == 3 and "c1.csv" not in str(e.value)


def test_parquet_is_read_by_device(tmp_path):
    table = gj.read_table(_tiny(tmp_path))
    path = str(tmp_path / "lot.parquet")
    gj.write_table(table, path)
    assert device_order(path) == ["a", "b", "c"]
    part = read_parquet_devices(path, ["b", "c"])
    assert sorted(set(part["device"].tolist())) == ["b", "c"] and len(part) == 4
    assert "[b .. c, 2 devices]" in part.source


def test_distributed_solve_arguments_are_checked():
    with pytest.raises(ValueError, match="exactly one"):
        DistributedSolve()
    with pytest.raises(ValueError, match="exactly one"):
        DistributedSolve(workers=2, scheduler="tcp://h:8786")
    with pytest.raises(ValueError, match="chunk must be an integer >= 1"):
        DistributedSolve(workers=2, chunk=0)
    with pytest.raises(ValueError, match="VmapSolve: pad_to"):
        gj.VmapSolve(pad_to=0)


def test_shared_parameters_are_refused(tmp_path):
    with pytest.raises(ValueError, match="shared couple the devices"):
        identify_lot("paper-qmg", _tiny(tmp_path), str(tmp_path / "o.json"), DistributedSolve(workers=1),
                     shared=("k_vf",))


def test_without_dask_the_error_says_how_to_install_it(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)
    out = str(tmp_path / "o.json")
    with pytest.raises(ImportError, match=r"pip install 'gyrojax\[distributed\]'"):
        identify_lot("paper-qmg", _tiny(tmp_path), out, DistributedSolve(workers=1))
    assert not os.path.exists(f"{out}.parts")


def test_a_restart_with_other_options_is_refused(tmp_path):
    path = _tiny(tmp_path)
    out = str(tmp_path / "o.json")
    plan = Plan(path, out, 2, {"free": "('k_vf',)"})
    assert plan.groups == [["a", "b"], ["c"]] and not plan.resumed
    assert Plan(path, out, 2, {"free": "('k_vf',)"}).resumed
    with pytest.raises(ValueError, match="belongs to another run \\(its options differ"):
        Plan(path, out, 2, {"free": "('q_y',)"})


def test_a_failed_chunk_is_reported_with_its_devices_and_the_merge_holds_every_device_once(tmp_path):
    rows = ["a,0,rate_table,1.0,101,0.1", "b,0,rate_table,1.0,nan,0.1"]
    path = _write(tmp_path / "bad.csv", rows)
    plan = Plan(path, str(tmp_path / "o.json"), 1, {})
    task = {"index": 1, "devices": ["b"], "first_device": 1, "data": path, "split_file": plan.split_files[1],
            "model": "paper-qmg", "options": {}, "chunk": 1, "result": plan.result(1), "failure": plan.failure(1)}
    assert fit_chunk(task)["failed"] == 1
    report = merge(plan)  # chunk 0 never ran, chunk 1 failed: both listed, with their devices
    assert [f["devices"] for f in report["failed"]] == [["a"], ["b"]]
    assert report["failed"][0]["error"] == "NotRun"
    assert report["failed"][1]["error"] == "DataError" and "bad.csv: data row 2 (line 3)" in report["failed"][1][
        "message"]
    assert report["exit_status"] == 1
    # A result file of a device the input does not hold breaks the every-device-once check.
    with open(plan.result(0), "w") as f:
        json.dump({"devices": [{"device": "z", "noise_dof": None}], "chi2": [1.0], "dof": [1], "unidentifiable": [],
                   "unidentifiable_directions": [], "compare": {}, "reject_alpha": 0.01}, f)
    with pytest.raises(RuntimeError, match=r"exactly once \(missing \['a'\], twice \[\], not in the input \['z'\]"):
        merge(plan)


def test_chunks_that_held_different_parameters_are_refused_at_the_merge(tmp_path):
    plan = Plan(_tiny(tmp_path), str(tmp_path / "o.json"), 2, {})

    def result(k, held):
        with open(plan.result(k), "w") as f:
            json.dump({"devices": [{"device": d, "noise_dof": None, "status": "ok"} for d in plan.groups[k]],
                       "chi2": [1.0] * len(plan.groups[k]), "dof": [1] * len(plan.groups[k]),
                       "unidentifiable": list(held), "reject_alpha": 0.01, "compare": {},
                       "unidentifiable_directions": [{"parameters": [h], "held": h, "singular_value": 1e-9 * (k + 1)}
                                                     for h in held]}, f)

    result(0, ["dac_gain_error"])
    result(1, ["dac_gain_error"])
    report = merge(plan)  # the same held in every chunk: merged, without the chunks' singular values
    assert report["unidentifiable_directions"] == [{"parameters": ["dac_gain_error"], "held": "dac_gain_error",
                                                    "singular_value": None}]
    result(1, ["dac_gain_error", "q_y"])
    with pytest.raises(ValueError, match=r"chunks held different parameters as unidentifiable \(chunk 0 held "
                                         r"dac_gain_error; chunk 1 held dac_gain_error, q_y\).*"
                                         r"hold=\('dac_gain_error', 'q_y'\)"):
        merge(plan)


def test_more_than_one_start_is_refused(tmp_path):
    out = str(tmp_path / "o.json")
    with pytest.raises(ValueError, match="more than one start draws every device's starts from one stream"):
        identify_lot("paper-qmg", _tiny(tmp_path), out, DistributedSolve(workers=1), start=gj.MultiStart(starts=2))
    assert not os.path.exists(f"{out}.parts")


def test_progress_line():
    assert progress_line(12, 2, 40, 4, 5.0) == "12/40 devices done, 2 failed, 2.00 devices/s, ETA 13 s"
    assert progress_line(40, 0, 40, 0, 8.0).endswith("ETA 0 s")


# -- on a local Dask cluster --------------------------------------------------------------------------------------

FREE = ("k_vf", "sense_gain")


def _lot_file(tmp_path_factory, devices: int) -> str:
    pytest.importorskip("distributed")
    path = str(tmp_path_factory.mktemp("lot") / f"lot{devices}.csv")
    gj.write_table(gj.simulate_table(gj.paper_qmg(), devices=devices, sweeps=("rate_table",), seed=3,
                                     progress=False), path)
    return path


@pytest.fixture(scope="module")
def lot8(tmp_path_factory):
    return _lot_file(tmp_path_factory, 8)


def _children():
    import psutil

    return [p for p in psutil.Process().children(recursive=True) if "spawn" in " ".join(p.cmdline())]


@pytest.fixture(scope="module")
def lot64(tmp_path_factory):
    return _lot_file(tmp_path_factory, 64)


@pytest.mark.slow
def test_a_lot_on_two_workers_one_killed_mid_run_is_the_single_process_fit_bit_for_bit(lot64, tmp_path, monkeypatch):
    import threading

    # the workers (spawned: they inherit the environment) compile their fit instead of loading it, so that a chunk
    # takes seconds on any machine and the kill below lands while chunks are still running
    monkeypatch.setenv("GYROJAX_CACHE_DIR", "off")
    monkeypatch.delenv("JAX_COMPILATION_CACHE_DIR", raising=False)  # (the suite's shared cache, conftest.py)

    out = str(tmp_path / "out.json")
    killed = {}

    def kill_one_worker():
        # A worker past its imports (~4 s of CPU) is working on a chunk: killed while the lot's 4 chunks are not all
        # done, the chunk it holds is lost with it and must be run again.
        deadline = time.time() + 300
        while time.time() < deadline:
            busy = [p for p in _children() if sum(p.cpu_times()[:2]) > 5.0]
            if busy:
                parts = f"{out}.parts"  # (made when the first chunk is written)
                done = [n for n in (os.listdir(parts) if os.path.isdir(parts) else ())
                        if n.startswith("chunk-") and n.endswith(".json")]
                if len(done) < 4:
                    killed["pid"], killed["chunks_done"] = busy[0].pid, len(done)
                    busy[0].kill()
                return
            time.sleep(0.2)

    killer = threading.Thread(target=kill_one_worker, daemon=True)
    killer.start()
    report = identify_lot("paper-qmg", lot64, out, DistributedSolve(workers=2, chunk=16), free=FREE, progress=False)
    killer.join(timeout=60)
    assert killed, "no worker was killed before the lot's chunks were all done"
    assert report["failed"] == [] and report["distributed"]["chunks"] == 4
    # One process solves the lot 16 devices at a time (VmapSolve's chunk on a CPU), as each chunk of 16 is:
    # the same program on the same numbers, so the same bits.
    fit = gj.identify("paper-qmg", gj.read_table(lot64), free=FREE, progress=False)
    assert [d["device"] for d in report["devices"]] == list(fit.devices)
    assert [d["status"] for d in report["devices"]] == list(fit.status)
    for k, name in enumerate(fit.names):
        for key, want in (("value", fit.values), ("stderr", fit.stderr)):
            got = [np.nan if d["parameters"][name][key] is None else d["parameters"][name][key]
                   for d in report["devices"]]
            np.testing.assert_array_equal(got, np.asarray(want[:, k]), err_msg=f"{name} {key}")
    np.testing.assert_array_equal([d["chi2_red"] for d in report["devices"]], np.asarray(fit.chi2_red))
    np.testing.assert_array_equal([d["p_value"] for d in report["devices"]], np.asarray(fit.p_value))
    assert report["chi2_red"] == float(fit.chi2_red_total) and report["p_value"] == float(fit.p_value_total)


@pytest.mark.slow
def test_a_killed_run_restarted_with_the_same_command_ends_with_every_device_once(lot8, tmp_path):
    out = str(tmp_path / "out.json")
    argv = [sys.executable, "-m", "gyrojax.cli", "identify", lot8, "--workers", "2", "--chunk", "1", "--free",
            ",".join(FREE), "--json", out]
    first = subprocess.Popen(argv, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                             start_new_session=True)
    parts = f"{out}.parts"
    done = []
    try:
        deadline = time.time() + 400
        while time.time() < deadline and first.poll() is None:
            done = sorted(n for n in os.listdir(parts) if n.startswith("chunk-") and n.endswith(".json")
                          and "failed" not in n) if os.path.isdir(parts) else []
            if done:
                break
            time.sleep(0.05)
    finally:
        os.killpg(first.pid, signal.SIGKILL)  # the run, its local cluster and its workers
        first.wait()
    assert done and len(done) < 8, f"the first run was not stopped mid-lot: {done}"
    stamps = {n: os.stat(os.path.join(parts, n)).st_mtime_ns for n in done}
    second = subprocess.run(argv, cwd=tmp_path, capture_output=True, text=True, timeout=500)
    assert second.returncode == 0, second.stderr[-3000:]
    assert "done by an earlier run, resuming" in second.stderr
    assert {n: os.stat(os.path.join(parts, n)).st_mtime_ns for n in done} == stamps  # not fitted again
    with open(out) as f:
        report = json.load(f)
    assert [d["device"] for d in report["devices"]] == device_order(lot8) and report["failed"] == []
    assert "8/8 devices done, 0 failed" in second.stderr


@pytest.mark.parametrize("extra,message", [
    ([], "--workers needs --json OUT.json"),
    (["--json", "o.json", "--save", "o.fit"], "--workers cannot be combined with --save"),
    (["--json", "o.json", "--population"], "--workers cannot be combined with --population"),
    (["--json", "o.json", "--scheduler", "tcp://h:8786"], "--workers cannot be combined with --scheduler"),
])
def test_identify_workers_refuses_what_needs_the_whole_lot(tmp_path, capsys, monkeypatch, extra, message):
    from gyrojax.cli import main

    monkeypatch.chdir(tmp_path)
    assert main(["identify", _tiny(tmp_path), "--workers", "2", *extra]) == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("option", [["--workers", "2"], ["--scheduler", "tcp://h:8786"]])
def test_diagnose_on_a_cluster_is_refused_with_the_reason(tmp_path, capsys, option):
    from gyrojax.cli import main

    assert main(["diagnose", _tiny(tmp_path), *option]) == 2
    err = capsys.readouterr().err
    assert f"{option[0]}: a diagnosis is not run in chunks of devices" in err and "identify --workers" in err


@pytest.mark.slow
def test_a_parquet_lot_on_an_existing_cluster_by_its_scheduler_address(lot8, tmp_path):
    from distributed import LocalCluster

    out, parquet = str(tmp_path / "out.json"), str(tmp_path / "lot8.parquet")
    gj.write_table(gj.read_table(lot8), parquet)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                      silence_logs=40) as cluster:
        report = identify_lot("paper-qmg", parquet, out, DistributedSolve(scheduler=cluster.scheduler_address,
                                                                          chunk=4), free=FREE, progress=False)
    assert [d["device"] for d in report["devices"]] == device_order(lot8) and report["failed"] == []
    assert not os.listdir(f"{out}.parts/input")  # read by device from the Parquet file, not split
    assert report["distributed"]["scheduler"] == cluster.scheduler_address


# -- the same fit whatever the chunking (in this process: fit_chunk on each chunk, as a worker runs it) ----------

def _chunked_in_process(path, out, chunk, model="paper-qmg", **options):
    from gyrojax._distributed.run import chunk_tasks

    plan = Plan(path, out, chunk, {})
    for task in chunk_tasks(plan, range(len(plan.groups)), model, {"free": FREE, **options}, chunk):
        fit_chunk(task)
    return merge(plan)


def _per_chunk_keys_dropped(report):
    """The merged report without what is per chunk by its name: the residual analysis of each chunk."""
    return {k: v for k, v in report.items() if k != "compare"}


@pytest.mark.slow
def test_the_estimated_noise_and_the_merged_report_do_not_depend_on_the_chunking(tmp_path):
    # Data without output_sigma: each device's noise is estimated and its p-value drawn by Monte Carlo, per
    # device with its position in the lot (not in its chunk); the lot's p-value is the F test of the pooled chi2.
    # Chunks of 16 and of 64 both solve 16 devices at a time (VmapSolve's chunk on a CPU), as one process does.
    table = gj.simulate_table(gj.paper_qmg(), devices=64, sweeps=("rate_table",), seed=5, progress=False)
    path = str(tmp_path / "lot.csv")
    gj.write_table(gj.Table({k: table[k] for k in table.column_names if k != "output_sigma"}), path)
    by_16 = _chunked_in_process(path, str(tmp_path / "o16.json"), 16)
    by_64 = _chunked_in_process(path, str(tmp_path / "o64.json"), 64)
    assert len(by_16["compare"]["by_chunk"]) == 4 and len(by_64["compare"]["by_chunk"]) == 1
    assert by_16["failed"] == [] and all(d["noise_dof"] is not None for d in by_16["devices"])
    assert _per_chunk_keys_dropped(by_16) == _per_chunk_keys_dropped(by_64)
    fit = gj.identify("paper-qmg", gj.read_table(path), free=FREE, progress=False)
    np.testing.assert_array_equal([d["p_value"] for d in by_16["devices"]], np.asarray(fit.p_value))
    np.testing.assert_array_equal([d["chi2_red"] for d in by_16["devices"]], np.asarray(fit.chi2_red))
    np.testing.assert_array_equal([d["noise_dof"] for d in by_16["devices"]], np.asarray(fit.noise_dof))
