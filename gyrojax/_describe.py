"""`gyrojax.describe`: every leaf of a device (and of the effects added to it) with its path, value, unit and
provenance, so that a user can find the path a new effect reads or writes (`vcf_electrode.force_per_volt2`)
without printing the device.

A leaf's path is the attribute path from the `Gyroscope` (`eqx.tree_at(lambda g: g.vcf_electrode.force_per_volt2,
...)`); an effect's leaves are `<effect name>.<field>`, as a fit names them. The unit is the named parameter's
(`gyrojax.PARAMETERS`) where the leaf is one, else what the docstring of the leaf's class says after the field's
description (`- \\`mass\\`: equivalent (modal) mass, kg.`). The provenance is the preset's own record: the
comment on the constant in `gyrojax/_presets.py` the leaf is set from (a seed table, or an ASSUMPTION and why);
leaves the preset does not set from a recorded constant have none.
"""

import dataclasses
import inspect
import re

import equinox as eqx
import jax
import numpy as np

from . import _presets
from ._device.file import is_device_file, parameter_paths, read_device_file, write_device_file
from ._gyroscope import Gyroscope
from ._model.parameters import DEFAULT_FREE, PARAMETERS, Model, as_model


class LeafRecord(eqx.Module):
    """One leaf: `path` (e.g. `"vcf_electrode.force_per_volt2"`), `value` (a float, or a tuple of floats for an
    array leaf), `unit` ("" where none is recorded or the number is dimensionless), `description` (the
    docstring's words for the field, "" if none) and `provenance` (the preset's record, "" if none)."""

    path: str
    value: float | tuple[float, ...]
    unit: str
    description: str
    provenance: str

    def to_json(self) -> dict:
        return dataclasses.asdict(self) | {"value": list(self.value) if isinstance(self.value, tuple)
                                           else self.value}


# Which constant of gyrojax/_presets.py each leaf of a preset is set from (the text is the constant's comment).
_FROM = {
    "paper-qmg": {
        "resonator.mass": ("QMG_MASS",), "resonator.omega_x": ("QMG_FX",),
        "resonator.omega_y": ("QMG_FX", "QMG_RESIDUAL_SPLIT"), "resonator.q_x": ("QMG_QX",),
        "resonator.q_y": ("QMG_QY",), "resonator.angular_gain": ("QMG_ANGULAR_GAIN",),
        "resonator.stiffness_coupling": ("QMG_QUADRATURE_DPS",), "resonator.tcf": ("SILICON_TCF",),
        "resonator.tcq": ("SILICON_TCQ",), "drive_electrode.force_per_volt": ("QMG_KDX",),
        "drive_frontend.current_per_velocity": ("QMG_KVI_X",), "sense_frontend.current_per_velocity": ("QMG_KVI_Y",),
        "drive_frontend.gain": ("QMG_CHARGE_GAIN",), "sense_frontend.gain": ("QMG_CHARGE_GAIN",),
        "drive_frontend.adc_lsb": ("QMG_ADC_LSB",), "sense_frontend.adc_lsb": ("QMG_ADC_LSB",),
        "drive_loop.center_frequency": ("QMG_FX",),
        "feedback_electrode.k_vf": ("QMG_SF", "QMG_KVF_PRINTED", "QMG_AMPLITUDE"),
        "feedback_electrode.v_dc": ("QMG_VDC",), "feedback_electrode.gap": ("QMG_GAP",),
        "excitation.dac.update_rate": ("QMG_DAC_UPDATE_RATE",), "excitation.dac.inl": ("QMG_INL_TERMS",),
        "excitation.amplifier_gain": ("QMG_AMPLIFIER_GAIN",),
        "vcf_electrode.force_per_volt2": ("QMG_VCF_DPS_PER_V2", "QMG_AMPLITUDE"),
    },
    "vcf-2018": {
        "resonator.mass": ("VCF_MASS",), "resonator.omega_x": ("VCF_WD",), "resonator.omega_y": ("VCF_WS",),
        "resonator.q_x": ("VCF_QD",), "resonator.q_y": ("VCF_QS",), "resonator.tcf": ("SILICON_TCF",),
        "resonator.tcq": ("SILICON_TCQ",), "drive_frontend.current_per_velocity": ("VCF_KYI",),
        "sense_frontend.current_per_velocity": ("VCF_KYI",), "drive_frontend.gain": ("VCF_SF_V_PER_DPS",),
        "sense_frontend.gain": ("VCF_SF_V_PER_DPS",), "drive_frontend.adc_lsb": ("VCF_ADC_LSB",),
        "sense_frontend.adc_lsb": ("VCF_ADC_LSB",), "drive_loop.amplitude_setpoint": ("VCF_DRIVE_VELOCITY",),
        "drive_loop.center_frequency": ("VCF_WD",), "readout.demod_cutoff": ("VCF_LPF_HZ",),
        "vcf_electrode.force_per_volt2": ("VCF_KSVF",),
    },
}
_LOOPS = {"drive_loop.pll_kp", "drive_loop.pll_ki", "drive_loop.agc_kp", "drive_loop.agc_ki",
          "drive_loop.demod_cutoff", "rebalance_loop.kp", "rebalance_loop.ki", "rebalance_loop.demod_cutoff"}

_UNIT = re.compile(r"^(?:[A-Za-z]{1,4}(?:\^-?\d)?(?:[/ ]\(?[A-Za-z]{1,4}(?:\^-?\d)?\)?)*|1/[A-Za-z()^\d ]+|deg C)$")


def _preset_comments() -> dict:
    """{constant name: its comment in gyrojax/_presets.py, continuation lines joined}."""
    out, last = {}, None
    for line in inspect.getsource(_presets).splitlines():
        m = re.match(r"^([A-Z][A-Z0-9_]*) = [^#]*#\s*(.*)$", line)
        if m:
            last = m.group(1)
            out[last] = m.group(2).strip()
            continue
        c = re.match(r"^\s*#\s{2,}(.*)$", line)  # a continuation: a comment indented under the first
        if c and last is not None:
            out[last] += " " + c.group(1).strip()
            continue
        last = None
    return out


def _provenance(preset: str | None, path: str, comments: dict) -> str:
    names = _FROM.get(preset, {}).get(path, ()) if preset is not None else ()
    parts = [f"{n}: {comments[n]}" for n in names if n in comments]
    if not parts and path in _LOOPS and preset in _FROM:
        parts = ["ASSUMPTION: loop designs are not printed; designed in gyrojax/_presets.py from the bandwidths "
                 "noted there (design_drive_loop, design_rebalance_loop)"]
    return "; ".join(parts)


def _field_docs(cls) -> dict:
    """{field: (description, unit)} from the `- \\`field\\`: words, unit.` lines of `cls`'s docstring."""
    out = {}
    for klass in getattr(cls, "__mro__", (cls,)):
        items = []  # (names, text): each bullet with its indented continuation lines joined
        for line in (klass.__doc__ or "").splitlines():
            m = re.match(r"^\s*- ((?:`\w+`(?:, )?)+): (.*)$", line)
            if m:
                items.append([m.group(1), m.group(2).strip()])
            elif items and items[-1] is not None and re.match(r"^\s{6,}\S", line):
                items[-1][1] += " " + line.strip()
            else:
                items.append(None) if items and items[-1] is not None else None
        for item in items:
            if item is None:
                continue
            names, text = item
            first = re.split(r"[;(]", text)[0].strip().rstrip(".")
            unit = first.rsplit(", ", 1)[1].strip() if ", " in first else ""
            unit = unit if _UNIT.match(unit) else ""
            for name in re.findall(r"`(\w+)`", names):
                out.setdefault(name, (text, unit))
    return out


def _records(tree, prefix: str, preset: str | None, comments: dict, named: dict) -> list:
    out = []
    for keys, leaf in jax.tree_util.tree_leaves_with_path(tree):
        attributes = [getattr(k, "name", None) for k in keys]
        names = [n for n in attributes if isinstance(n, str)]
        if len(names) != len(attributes):  # only attribute paths (a Module's fields) are user-facing
            continue
        path = ".".join([prefix] + names if prefix else names)
        owner = tree
        for n in names[:-1]:
            owner = getattr(owner, n)
        desc, unit = _field_docs(type(owner)).get(names[-1], ("", ""))
        if path in named:
            unit = named[path].unit or unit
            desc = desc or named[path].description
        arr = np.asarray(leaf, dtype=float)
        value = float(arr) if arr.ndim == 0 else tuple(float(x) for x in arr.ravel())
        out.append(LeafRecord(path=path, value=value, unit=unit, description=desc,
                              provenance=_provenance(preset, path, comments)))
    return out


def _named_paths(gyro) -> dict:
    """{leaf path: Parameter} of the named physical parameters the device has."""
    out = {}
    leaves = {id(leaf): ".".join(getattr(k, "name", "?") for k in keys)
              for keys, leaf in jax.tree_util.tree_leaves_with_path(gyro)}
    for p in PARAMETERS.values():
        if not p.exists_on(gyro):
            continue
        try:
            path = leaves.get(id(p.where(gyro)))
        except AttributeError:  # the device lacks the part (an open-loop device has no feedback electrode)
            continue
        if path is not None:
            out[path] = p
    return out


def describe(model: Model | Gyroscope | str = "paper-qmg") -> tuple[LeafRecord, ...]:
    """Every leaf of `model` (a preset name, a `Gyroscope` or a `gyrojax.Model`; effects included, as
    `<effect>.<field>`), in the device's order: a tuple of `LeafRecord` (path, value, unit, description,
    provenance). A preset (by name, or a device whose `name` is a preset's) carries the provenance recorded in
    `gyrojax/_presets.py`. Raises `ValueError` for an unknown preset name and `TypeError` for anything else."""
    file_provenance = None
    if isinstance(model, str) and is_device_file(model):
        device_file = read_device_file(model)
        model, file_provenance = device_file.device, device_file.provenance
    elif isinstance(model, str) and model not in _presets.PRESETS:
        raise ValueError(f"describe: unknown preset {model!r}; expected one of {sorted(_presets.PRESETS)} or a "
                         "device file (.toml).")
    m = as_model(model)
    leaf = jax.tree_util.tree_leaves(m.device)
    if any(np.ndim(x) > 0 and np.shape(x)[0] > 1 for x in leaf) and _is_lot(m.device):
        raise ValueError("describe: the device is a lot (leaves with a leading device axis); describe one device.")
    preset = getattr(m.device, "name", None)
    preset = preset if preset in _presets.PRESETS and file_provenance is None else None
    comments = _preset_comments()
    records = _records(m.device, "", preset, comments, _named_paths(m.device))
    if file_provenance is not None:  # a device file's own record, not a preset's
        records = [dataclasses.replace(r, provenance=file_provenance.get(r.path, "")) for r in records]
    for eff in m.effects:
        records += _records(eff, eff.name, None, comments, {})
    return tuple(records)


def write_toml(model, path) -> None:
    """Write `model` (a preset name, a device file, or one `Gyroscope`) as a device file at `path`: every leaf with
    its unit, description and provenance (`describe`'s), and `free = true` on the parameters a fit frees by
    default (`gyrojax.identification.DEFAULT_FREE`, those the device has), or on a device file's own free ones."""
    records = describe(model)
    if isinstance(model, str) and is_device_file(model):
        device_file = read_device_file(model)
        gyro, free, source = device_file.device, device_file.free, model
    else:
        gyro = as_model(model).device
        if as_model(model).effects:
            raise ValueError("describe: a model with effects cannot be written as a device file (an effect is "
                             "fitted from zero, not described); write its device.")
        free, source = DEFAULT_FREE, (f"preset {model!r} (gyrojax/_presets.py)" if isinstance(model, str) else "")
    free = tuple(n for n in free if n in parameter_paths(gyro).values())
    write_device_file(gyro, path, provenance={r.path: r.provenance for r in records}, free=free,
                      descriptions={r.path: r.description for r in records}, source=source)


def _is_lot(gyro) -> bool:
    mass = np.asarray(gyro.resonator.mass)
    return mass.ndim > 0


def _value_text(value) -> str:
    if isinstance(value, tuple):
        return "[" + ", ".join(f"{v:.6g}" for v in value) + "]"
    return f"{value:.6g}"


def describe_text(records, *, provenance: bool = True) -> str:
    """The records as aligned lines: path, value, unit, then the description and provenance indented."""
    width = max((len(r.path) for r in records), default=0)
    lines = []
    for r in records:
        lines.append(f"{r.path:<{width}}  {_value_text(r.value):>14}  {r.unit}".rstrip())
        if r.description:
            lines.append(f"{'':<{width}}    {r.description}")
        if provenance and r.provenance:
            lines.append(f"{'':<{width}}    from: {r.provenance}")
    return "\n".join(lines)
