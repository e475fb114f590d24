"""experiments/seed_closure.py: the numbers that do and do not close in the seeds."""


import pytest
from _experiments import load_experiment


def _load():
    return load_experiment("seed_closure")


def test_seed_closure_numbers(tmp_path, capsys):
    out = _load().main(["--json", str(tmp_path / "closure.json")])
    s0, s3 = out["seed000"], out["seed003"]
    # Table 1's K_vf is ~214x too small for 1.637 V at 200 deg/s with a 5 um drive
    assert s0["kvf_ratio"] == pytest.approx(214, rel=0.01)
    assert s0["drive_amplitude_with_printed_kvf_m"] == pytest.approx(23.3e-9, rel=0.01)
    # Table 2's DAC scale closes to 5 V / 2^23 within 0.05 %
    assert abs(s0["dac_scale_mismatch_ppm"]) < 500
    assert s0["model_sf_lsb_per_dps"] == pytest.approx(13709.853, rel=1e-9)
    # seed 003: the model's bandwidth is ~1.55 x the detuning, far below the reported 354.3 Hz
    assert s3["bandwidth_model_hz"] == pytest.approx(s3["bandwidth_1p55_split_hz"], rel=0.01)
    assert s3["bandwidth_model_hz"] < 0.3 * s3["bandwidth_paper_measured_hz"]
    assert s3["pulling_ppm_at_200dps_model"] == pytest.approx(s3["pulling_ppm_at_200dps_law_minus"], rel=0.05)
    assert "DOES NOT CLOSE" in capsys.readouterr().out
    assert (tmp_path / "closure.json").exists()
