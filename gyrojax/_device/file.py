"""Device files: a gyroscope described in TOML, one section per part, every value with its unit.

```toml
name = "my-gyro"
phase_points = 16

[resonator]
omega_x = { value = 10178.0, unit = "Hz", free = true, provenance = "our FEM, rev C" }
q_x = { value = 5.1e5, unit = "1" }
...
[excitation.dac]
bits = 18
full_scale = { value = 2.5, unit = "V" }
```

The sections are the device's parts (`resonator`, `drive_electrode`, `drive_frontend`, `sense_frontend`,
`drive_loop`, `feedback_electrode`, `excitation`, `excitation.dac`, `rebalance_loop` for a closed-loop device or
`readout` for an open-loop one, `vcf_electrode`, `temperature`), and the keys their fields: the paths of
`gyrojax describe`. A value is a table `{value, unit, free, provenance}`: the unit is checked against the leaf's
quantity and converted to SI (`units.py`), `free = true` marks a named parameter (`gyrojax.PARAMETERS`) that
`identify` frees, the provenance is kept for `describe`. A dimensionless value may be a bare number. Settings
that are not parameters (`bits`, `demod_order`, a front end's `kind`) are plain values. A field left out takes
the class's default; one without a default is required.

`write_device_file` writes floats with `repr` in the canonical (SI) unit, so that reading back gives every leaf
bit for bit.
"""

import dataclasses
import difflib
import json
import math
import os
import tomllib
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .._control.drive import DriveLoop
from .._control.openloop import OpenLoopReadout
from .._control.rebalance import RebalanceLoop
from .._electronics.dac import DAC
from .._electronics.excitation import FTRExcitation
from .._electronics.frontend import FrontEnd
from .._gyroscope import Gyroscope
from .._lots.stack import as_arrays
from .._model.catalog import PARAMETERS
from .._physics.electrodes import DriveElectrode, FeedbackElectrode, VirtualCoriolisElectrode
from .._physics.resonator import Resonator
from .._physics.thermal import ConstantTemperature, PlateauTemperature, WarmupTemperature
from .._units import rad_s_to_hz
from .lock import lock_problems
from .units import accepted_units, canonical_unit, factor_to_si, quantity_of


class DeviceFileError(ValueError):
    """A device file gyrojax refuses: the message names the file, the section and the key."""


SECTIONS = {
    "resonator": Resonator, "drive_electrode": DriveElectrode, "drive_frontend": FrontEnd,
    "sense_frontend": FrontEnd, "drive_loop": DriveLoop, "feedback_electrode": FeedbackElectrode,
    "excitation": FTRExcitation, "excitation.dac": DAC, "rebalance_loop": RebalanceLoop, "readout": OpenLoopReadout,
    "vcf_electrode": VirtualCoriolisElectrode, "temperature": None,
}
"""Section name: the class it builds (the temperature's class is its `kind`)."""

TEMPERATURE_KINDS = {"constant": ConstantTemperature, "warmup": WarmupTemperature, "plateau": PlateauTemperature}
_REQUIRED = ("resonator", "drive_electrode", "drive_frontend", "sense_frontend", "drive_loop")
_TOP_KEYS = ("name", "phase_points")
_VALUE_KEYS = ("value", "unit", "free", "provenance")

# Values no device can have, with the physical reason (leaves not listed are checked by their classes).
_POSITIVE_WHY = {
    "angular frequency": "a frequency is > 0 (a negative one is the same oscillation with its phase reversed; a "
                         "zero one does not oscillate)",
    "frequency": "a frequency is > 0",
    "mass": "a mass is > 0",
    "length": "a gap is > 0",
    "time": "a time constant is > 0",
}
_SPECIFIC_WHY = {
    ("Resonator", "q_x"): "a quality factor is > 0 (Q = w / bandwidth of the resonance; Q <= 0 is a mode that "
                          "is not damped but self-oscillates)",
    ("Resonator", "q_y"): "a quality factor is > 0 (Q = w / bandwidth of the resonance; Q <= 0 is a mode that "
                          "is not damped but self-oscillates)",
    ("Resonator", "angular_gain"): "the angular gain Ag is > 0 (the share of the mass that carries the Coriolis "
                                   "force)",
    ("DriveLoop", "amplitude_setpoint"): "the AGC set-point is the drive amplitude the AGC holds; at zero (or "
                                         "below) it holds the drive at rest: no drive motion, no Coriolis force, "
                                         "no rate output",
    ("DAC", "full_scale"): "a DAC's full scale is > 0",
    ("FeedbackElectrode", "v_dc"): "the feedback combs' bias is > 0 (their force per volt is proportional to it)",
    ("FeedbackElectrode", "k_vf"): "the feedback force per volt is > 0 (a negative one is a loop with its sign "
                                   "reversed: it cannot lock)",
    ("DriveElectrode", "force_per_volt"): "the drive force per volt is > 0 (a negative one reverses the AGC's "
                                          "sign: it cannot lock)",
    ("FrontEnd", "adc_lsb"): "an ADC's LSB is > 0",
    ("FrontEnd", "current_per_velocity"): "a pick-off's current per velocity is > 0",
    ("FTRExcitation", "amplifier_gain"): "the feedback amplifier's gain is > 0 (a negative one reverses the "
                                         "rebalance loop's sign)",
}
_LOOP_GAINS = {("DriveLoop", f) for f in ("pll_kp", "pll_ki", "agc_kp", "agc_ki")} | {
    ("RebalanceLoop", "kp"), ("RebalanceLoop", "ki")}


@dataclasses.dataclass(frozen=True)
class DeviceFile:
    """A device file read: `device` (one `Gyroscope`), `free` (the names of `gyrojax.PARAMETERS` marked
    `free = true`, in the file's order), `provenance` ({leaf path: text}) and `path`."""

    device: Gyroscope
    free: tuple[str, ...]
    provenance: dict
    path: str


def is_device_file(text) -> bool:
    """Whether a model argument names a device file (a path ending in .toml) rather than a preset."""
    return isinstance(text, (str, os.PathLike)) and os.fspath(text).lower().endswith(".toml")


def _nearest(key: str, valid) -> str:
    near = difflib.get_close_matches(key, list(valid), n=1, cutoff=0.6)
    return f"; did you mean {near[0]!r}?" if near else f"; valid keys: {', '.join(valid)}"


def _fields(cls):
    return [f for f in dataclasses.fields(cls)]


def _is_static(f) -> bool:
    return bool(f.metadata.get("static", False))


def _has_default(f) -> bool:
    return f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING


def _subsections(cls) -> dict:
    return {"dac": DAC} if cls is FTRExcitation else {}


def parameter_paths(gyro: Gyroscope) -> dict:
    """{leaf path: name} of the named parameters (`gyrojax.PARAMETERS`) that one device has."""
    leaves = {id(leaf): ".".join(getattr(k, "name", "?") for k in keys)
              for keys, leaf in jax.tree_util.tree_leaves_with_path(gyro)}
    out = {}
    for p in PARAMETERS.values():
        if not p.exists_on(gyro):
            continue
        try:
            path = leaves.get(id(p.where(gyro)))
        except AttributeError:  # the device lacks the part
            continue
        if path is not None:
            out[path] = p.name
    return out


# --- reading --------------------------------------------------------------------------------------------------

class _Reader:
    def __init__(self, path: str):
        self.path = path
        self.free_paths: list[str] = []
        self.provenance: dict = {}

    def fail(self, where: str, text: str):
        raise DeviceFileError(f"{self.path}: {where}: {text}")

    def value(self, section: str, cls, field: str, entry, frontend_kind):
        where = f"[{section}] {field}"
        quantity = quantity_of(cls.__name__, field, frontend_kind)
        unit_hint = f"{canonical_unit(quantity)!r} ({quantity}; accepted: {accepted_units(quantity)})"
        if isinstance(entry, dict):
            for key in entry:
                if key not in _VALUE_KEYS:
                    self.fail(where, f"unknown key {key!r} in the value's table{_nearest(key, _VALUE_KEYS)}")
            if "value" not in entry:
                self.fail(where, f"no value: write {field} = {{ value = ..., unit = {canonical_unit(quantity)!r} }}")
            raw, unit = entry["value"], entry.get("unit")
            if unit is not None and not isinstance(unit, str):
                self.fail(where, f"the unit must be a string such as {unit_hint}, got {unit!r}")
            free = entry.get("free", False)
            if not isinstance(free, bool):
                self.fail(where, f"free must be true or false, got {free!r}")
            if free:
                self.free_paths.append(f"{section}.{field}")
            prov = entry.get("provenance", "")
            if not isinstance(prov, str):
                self.fail(where, f"the provenance must be a string, got {prov!r}")
            if prov:
                self.provenance[f"{section}.{field}"] = prov
        else:
            raw, unit = entry, None
        if unit is None:
            if factor_to_si(quantity, "1") != 1.0:
                self.fail(where, f"no unit: a value of {quantity} needs one, e.g. {field} = {{ value = "
                                 f"{raw!r}, unit = {canonical_unit(quantity)!r} }} (accepted: "
                                 f"{accepted_units(quantity)})")
            unit = "1"
        factor = factor_to_si(quantity, unit)
        if factor is None:
            self.fail(where, f"unit {unit!r} is not a unit of this leaf's quantity ({quantity}); accepted: "
                             f"{accepted_units(quantity)}")
        numbers = raw if isinstance(raw, list) else [raw]
        if not numbers or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in numbers):
            self.fail(where, f"the value must be a number{' or a list of numbers' if isinstance(raw, list) else ''}"
                             f", got {raw!r}")
        si = [float(x) if factor == 1.0 else float(x) * factor for x in numbers]
        self.check_value(where, cls, field, quantity, si, numbers, unit)
        return si if isinstance(raw, list) else si[0]

    def check_value(self, where, cls, field, quantity, si, given, unit):
        key = (cls.__name__, field)
        for x, g in zip(si, given):
            shown = f"{g!r} {unit}".rstrip(" 1") if unit == "1" else f"{g!r} {unit}"
            if math.isnan(x) or (math.isinf(x) and key != ("DAC", "update_rate")):
                self.fail(where, f"{shown} is not a finite number")
            why = _SPECIFIC_WHY.get(key) or _POSITIVE_WHY.get(quantity)
            if key in _LOOP_GAINS:
                why = ("a PI gain of a loop is > 0: a zero gain leaves the loop open, a negative one reverses its "
                       "sign, and either way the loop cannot lock")
            if why is not None and x <= 0.0:
                self.fail(where, f"{shown} is impossible: {why}")

    def section(self, name: str, cls, table) -> object:
        if not isinstance(table, dict):
            self.fail(f"[{name}]", f"must be a section (a table), got {table!r}")
        subs = _subsections(cls)
        fields = _fields(cls)
        valid = [f.name for f in fields if f.name not in subs] + list(subs)
        if name == "temperature":
            valid = ["kind"] + valid
        for key in table:
            if key not in valid:
                self.fail(f"[{name}]", f"unknown key {key!r}{_nearest(key, valid)}")
        kind = table.get("kind") if cls is FrontEnd else None
        kwargs: dict[str, Any] = {}  # parsed from the file; `cls` checks the values
        for f in fields:
            if f.name in subs:
                if f.name in table:
                    kwargs[f.name] = self.section(f"{name}.{f.name}", subs[f.name], table[f.name])
                elif not _has_default(f):
                    self.fail(f"[{name}]", f"missing section [{name}.{f.name}]")
                continue
            if f.name not in table:
                if not _has_default(f):
                    q = quantity_of(cls.__name__, f.name, kind)
                    self.fail(f"[{name}]", f"missing {f.name} ({q}, in {canonical_unit(q)!r}); "
                                           "`gyrojax describe --toml` writes every key")
                continue
            entry = table[f.name]
            if _is_static(f):
                kwargs[f.name] = self.setting(name, f, entry)
            else:
                kwargs[f.name] = self.value(name, cls, f.name, entry, kind)
        # A list is an array leaf (a DAC's INL), or a tuple field of a plateau history.
        kwargs = {k: (tuple(v) if cls is PlateauTemperature else jnp.asarray(v, dtype=float))
                  if isinstance(v, list) else v for k, v in kwargs.items()}
        try:
            return cls(**kwargs)
        except (TypeError, ValueError) as e:
            self.fail(f"[{name}]", str(e))

    def setting(self, section: str, f, entry):
        where = f"[{section}] {f.name}"
        expected = {int: "a whole number", bool: "true or false", str: "a string"}
        kind = type(f.default) if f.default is not dataclasses.MISSING else None
        if kind in expected and (type(entry) is not kind):
            self.fail(where, f"is a setting, not a parameter: {expected[kind]} without a unit, got {entry!r}")
        return entry


def read_device_file(path) -> DeviceFile:
    """Read and check a device file (see the module docstring): `DeviceFile` with the device, the free
    parameters and the provenance. Raises `DeviceFileError` (a `ValueError`) naming the file, the section and
    the key for a file gyrojax refuses: a TOML syntax error, an unknown key (with the nearest valid one), a unit
    that is not one of the quantity's, an impossible value (a frequency or Q <= 0, a zero AGC set-point), a loop
    that cannot lock, `free` on a leaf that is not a named parameter."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(2, "no such device file (write one with `gyrojax describe --model PRESET --toml "
                                   "FILE.toml`)", path)
    with open(path, "rb") as f:
        data = f.read()
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise DeviceFileError(f"{path}: not a UTF-8 text file: {e}") from None
    return device_from_text(text, path)


def device_from_text(text: str, path: str = "<text>", *, check_loops: bool = True) -> DeviceFile:
    """`read_device_file` of a device file's text (`path` names it in messages). `check_loops=False` skips the
    loops' lock check (a saved fit rebuilds its device's structure from the text it stored)."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise DeviceFileError(f"{path}: not a valid TOML file: {e}") from None
    reader = _Reader(path)
    valid = list(_TOP_KEYS) + [s for s in SECTIONS if "." not in s]
    for key in doc:
        if key not in valid:
            reader.fail("top level", f"unknown key or section {key!r}{_nearest(key, valid)}")
    for s in _REQUIRED:
        if s not in doc:
            reader.fail(f"[{s}]", "missing section (`gyrojax describe --model PRESET --toml FILE.toml` writes a "
                                  "complete file to start from)")
    closed, opened = "rebalance_loop" in doc, "readout" in doc
    if closed == opened:
        reader.fail("top level", "give exactly one of [rebalance_loop] (a closed-loop, force-to-rebalance device, "
                                 "with [feedback_electrode] and [excitation]) or [readout] (an open-loop device)"
                                 + (", not both" if closed else ", got neither"))
    if closed and not ("feedback_electrode" in doc and "excitation" in doc):
        reader.fail("[rebalance_loop]", "a closed-loop device needs [feedback_electrode] and [excitation] too")
    if opened:
        for s in ("feedback_electrode", "excitation"):
            if s in doc:
                reader.fail(f"[{s}]", "an open-loop device (with [readout]) has no feedback combs nor FTR "
                                      "excitation: remove the section, or give [rebalance_loop] instead of [readout]")
    parts = {}
    for name, cls in SECTIONS.items():
        if "." in name or name not in doc:
            continue
        if name == "temperature":
            table = doc[name]
            kind = table.get("kind", "constant") if isinstance(table, dict) else None
            if kind not in TEMPERATURE_KINDS:
                reader.fail("[temperature] kind", f"must be one of {', '.join(TEMPERATURE_KINDS)}, got {kind!r}")
            cls = TEMPERATURE_KINDS[kind]
            table = {k: v for k, v in table.items() if k != "kind"}
            parts[name] = reader.section(name, cls, table | {"kind": kind})
            continue
        parts[name] = reader.section(name, cls, doc[name])
    name = doc.get("name", os.path.splitext(os.path.basename(path))[0])
    phase_points = doc.get("phase_points", 16)
    if not isinstance(name, str) or not name:
        reader.fail("top level name", f"must be a non-empty string, got {name!r}")
    if type(phase_points) is not int:
        reader.fail("top level phase_points", f"must be a whole number, got {phase_points!r}")
    try:
        gyro = Gyroscope(**parts, name=name, phase_points=phase_points)
    except (TypeError, ValueError) as e:
        reader.fail("device", str(e))
    gyro = as_arrays(gyro)
    problems = lock_problems(gyro) if check_loops else []
    if problems:
        reader.fail("loops", "; ".join(problems))
    named = parameter_paths(gyro)
    free = []
    for p in reader.free_paths:
        if p not in named:
            section, field = p.rsplit(".", 1)
            reader.fail(f"[{section}] {field}",
                        f"free = true on a leaf that is not a parameter a fit can free; the leaves that can be: "
                        f"{', '.join(named)} ({', '.join(named.values())} in gyrojax.PARAMETERS)")
        free.append(named[p])
    return DeviceFile(gyro, tuple(free), dict(reader.provenance), path)


def load_device(path: str | os.PathLike) -> Gyroscope:
    """The device a device file describes (TOML, see docs/own_device.md), checked: its units converted, its
    values possible, its loops able to lock. Raises a `ValueError` naming the file, section and key otherwise.
    Write one to start from with `gyrojax describe --model PRESET --toml FILE.toml`."""
    return read_device_file(path).device


# --- writing --------------------------------------------------------------------------------------------------

def _toml_string(text: str) -> str:
    return json.dumps(text, ensure_ascii=False)  # a JSON string is a TOML basic string


def _float_text(x: float) -> str:
    return repr(float(x))  # repr round-trips every float64 exactly; TOML reads inf and nan as written


def _friendly(quantity: str, value) -> str:
    if quantity == "angular frequency" and not isinstance(value, list):
        return f" ({rad_s_to_hz(value):.6g} Hz)"
    return ""


def _leaf_value(leaf):
    arr = np.asarray(leaf, dtype=float)
    if arr.ndim == 0:
        return float(arr)
    return [float(x) for x in arr.ravel()]


def _write_section(lines, name, module, prefix, provenance, free_paths, descriptions):
    cls = type(module)
    kind = getattr(module, "kind", None) if isinstance(module, FrontEnd) else None
    lines += ["", f"[{name}]"]
    if name == "temperature":
        kind_name = {v: k for k, v in TEMPERATURE_KINDS.items()}.get(cls)
        if kind_name is None:
            raise ValueError(f"write_device_file: a temperature history of type {cls.__name__} cannot be written "
                             f"as a device file (the kinds are {', '.join(TEMPERATURE_KINDS)}).")
        lines.append(f"kind = {_toml_string(kind_name)}")
    subs = []
    for f in _fields(cls):
        value = getattr(module, f.name)
        path = f"{prefix}.{f.name}"
        if f.name in _subsections(cls):
            subs.append((f"{name}.{f.name}", value, path))
            continue
        if _is_static(f):
            text = _toml_string(value) if isinstance(value, str) else ("true" if value is True else "false"
                                                                      if value is False else str(int(value)))
            lines.append(f"{f.name} = {text}")
            continue
        quantity = quantity_of(cls.__name__, f.name, kind)
        v = _leaf_value(value)
        number = "[" + ", ".join(_float_text(x) for x in v) + "]" if isinstance(v, list) else _float_text(v)
        parts = [f"value = {number}", f"unit = {_toml_string(canonical_unit(quantity))}"]
        if path in free_paths:
            parts.append("free = true")
        if provenance.get(path):
            parts.append(f"provenance = {_toml_string(provenance[path])}")
        desc = descriptions.get(path, "")
        comment = (desc + _friendly(quantity, v)).strip()
        if comment:
            lines.append("# " + " ".join(comment.split()))
        lines.append(f"{f.name} = {{ {', '.join(parts)} }}")
    for sub_name, sub, sub_path in subs:
        _write_section(lines, sub_name, sub, sub_path, provenance, free_paths, descriptions)


def device_file_text(gyro: Gyroscope, *, provenance: dict | None = None, free=(), descriptions: dict | None = None,
                     source: str = "") -> str:
    """The TOML text of one device (see `write_device_file`)."""
    if not isinstance(gyro, Gyroscope):
        raise TypeError(f"write_device_file: expected a gyrojax.Gyroscope, got {type(gyro).__name__}.")
    if np.ndim(gyro.resonator.mass) > 0:
        raise ValueError("write_device_file: the device is a lot (leaves with a leading device axis); write one "
                         "device.")
    if gyro.terms:
        raise ValueError(f"write_device_file: the device carries {len(gyro.terms)} term(s) "
                         f"({', '.join(type(t).__name__ for t in gyro.terms)}): a term is code, not a value, and a "
                         "device file holds values only; write the device without them and add them in Python.")
    named = parameter_paths(gyro)
    unknown = [n for n in free if n not in named.values()]
    if unknown:
        raise ValueError(f"write_device_file: free names {unknown} are not parameters this device has "
                         f"({', '.join(named.values())}).")
    free_paths = {p for p, n in named.items() if n in free}
    lines = ["# gyrojax device file (docs/own_device.md): one section per part of the device, every value with its",
             "# unit (converted on reading), `free = true` on the parameters a fit frees, and where each value comes",
             "# from. Frequencies are written in rad/s (exact); \"Hz\", \"kHz\" are accepted too."]
    if source:
        lines.append(f"# Written from {source}.")
    lines += [f"name = {_toml_string(gyro.name)}", f"phase_points = {int(gyro.phase_points)}"]
    for f in _fields(Gyroscope):
        value = getattr(gyro, f.name)
        if f.name in _TOP_KEYS or f.name == "terms" or value is None:
            continue
        _write_section(lines, f.name, value, f.name, provenance or {}, free_paths, descriptions or {})
    return "\n".join(lines) + "\n"


def write_device_file(gyro: Gyroscope, path, *, provenance: dict | None = None, free=(),
                      descriptions: dict | None = None, source: str = "") -> None:
    """Write one device as a device file at `path` (atomically): every leaf in its canonical (SI) unit with
    `repr`, so that `read_device_file` gives it back bit for bit; `free` (names of `gyrojax.PARAMETERS`) marked
    `free = true`; `provenance` and `descriptions` ({leaf path: text}) as each value's provenance and comment."""
    from .._data.io import atomic_write_bytes

    atomic_write_bytes(path, device_file_text(gyro, provenance=provenance, free=free, descriptions=descriptions,
                                              source=source).encode("utf-8"))
