"""`gyrojax describe`: every leaf of a preset with its path, value, unit and the preset's provenance."""

import json

import jax
import pytest

import gyrojax as gj
from gyrojax._describe import LeafRecord, describe, describe_text
from gyrojax.cli import main


def test_every_leaf_of_the_device_is_listed_with_its_path_and_value():
    g = gj.preset("paper-qmg")
    records = describe("paper-qmg")
    by_path = {r.path: r for r in records}
    assert all(isinstance(r, LeafRecord) for r in records)
    # the path a new effect reads, with the device's value
    vcf = by_path["vcf_electrode.force_per_volt2"]
    assert vcf.value == pytest.approx(float(g.vcf_electrode.force_per_volt2), rel=1e-15)
    assert vcf.unit == "N/V^2"
    assert vcf.provenance.startswith("QMG_VCF_DPS_PER_V2: deg/s per V^2 of V_ac V_fc, ASSUMPTION")
    # an array leaf keeps its elements; a unit from the class's docstring; a seed table as provenance
    assert by_path["excitation.dac.inl"].value == (0.0, 0.0, 0.0, 0.0)
    assert by_path["resonator.mass"].unit == "kg" and 'Table 1 "Mass 1.56 mg"' in by_path["resonator.mass"].provenance
    assert by_path["feedback_electrode.k_vf"].unit == "N/V"
    assert "does NOT close" in by_path["feedback_electrode.k_vf"].provenance
    # every leaf, each once, in the device's order
    leaves = jax.tree_util.tree_leaves(g)
    assert len(records) == len(leaves) and len(by_path) == len(records)


def test_an_effect_is_listed_under_its_name_and_a_bad_model_is_refused():
    model = gj.Model(gj.preset("vcf-2018"), (gj.EFFECTS["vref_drift"].typical(1.0),))
    paths = [r.path for r in describe(model)]
    assert paths[0] == "resonator.mass" and any(p.startswith("vref_drift.") for p in paths)
    vcf = {r.path: r for r in describe("vcf-2018")}["vcf_electrode.force_per_volt2"]
    assert vcf.provenance.startswith("VCF_KSVF: N/V, Table 1")
    with pytest.raises(ValueError, match="describe: unknown preset 'qmg'; expected one of"):
        describe("qmg")


def test_the_command_prints_and_writes_the_records(tmp_path, capsys):
    out = tmp_path / "leaves.json"
    assert main(["describe", "--model", "paper-qmg", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "vcf_electrode.force_per_volt2" in text and "from: QMG_VCF_DPS_PER_V2" in text
    records = json.loads(out.read_text())
    assert set(records[0]) == {"path", "value", "unit", "description", "provenance"}
    assert describe_text(describe("paper-qmg")).splitlines()[0].startswith("resonator.mass")
