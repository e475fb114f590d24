"""The units a device file may give each leaf in, and the factor to SI (the unit the code uses inside).

Every leaf of a device has a quantity (`LEAF_QUANTITY`, keyed by the leaf's class and field); a quantity has a
canonical unit (the SI unit of the code, written by `write_device_file` with factor 1, so that a round trip is
exact) and the other units it accepts, each with its factor to the canonical one.
"""

import math

from .._units import DEG


# quantity: (canonical unit, {accepted unit: factor to the canonical unit}); the canonical unit comes first.
QUANTITIES = {
    "angular frequency": {"rad/s": 1.0, "Hz": 2.0 * math.pi, "kHz": 2.0e3 * math.pi, "MHz": 2.0e6 * math.pi},
    "frequency": {"Hz": 1.0, "kHz": 1e3, "MHz": 1e6},
    "rate constant": {"1/s": 1.0},
    "rate constant squared": {"1/s^2": 1.0},
    "stiffness per unit mass": {"rad^2/s^2": 1.0, "1/s^2": 1.0},
    "cubic stiffness per unit mass": {"1/(m^2 s^2)": 1.0},
    "mass": {"kg": 1.0, "g": 1e-3, "mg": 1e-6, "ug": 1e-9},
    "length": {"m": 1.0, "mm": 1e-3, "um": 1e-6, "nm": 1e-9},
    "voltage": {"V": 1.0, "mV": 1e-3, "uV": 1e-6},
    "dimensionless": {"1": 1.0, "%": 1e-2, "ppm": 1e-6},
    "temperature coefficient": {"1/K": 1.0, "ppm/K": 1e-6, "%/K": 1e-2},
    "temperature": {"degC": 1.0},
    "temperature difference": {"K": 1.0},
    "time": {"s": 1.0, "ms": 1e-3, "min": 60.0, "h": 3600.0},
    "angle": {"rad": 1.0, "mrad": 1e-3, "deg": DEG},
    "force per volt": {"N/V": 1.0, "uN/V": 1e-6, "nN/V": 1e-9},
    "force per volt squared": {"N/V^2": 1.0, "uN/V^2": 1e-6},
    "current per velocity": {"A/(m/s)": 1.0},
    "charge-amplifier gain": {"V/C": 1.0, "V/pC": 1e12},
    "transimpedance": {"V/A": 1.0, "V/uA": 1e6},
    "ADC word": {"LSB": 1.0},
    "AGC proportional gain": {"V/LSB": 1.0},
    "AGC integral gain": {"V/(LSB s)": 1.0},
}

# Spellings of a unit that mean the same (the canonical spelling on the right).
ALIASES = {"deg C": "degC", "°C": "degC", "µm": "um", "µg": "ug", "µV": "uV", "": "1"}

# (class name, field): quantity. A frontend's gain is "gain" (its unit follows the frontend's kind).
LEAF_QUANTITY = {
    ("Resonator", "mass"): "mass",
    ("Resonator", "omega_x"): "angular frequency",
    ("Resonator", "omega_y"): "angular frequency",
    ("Resonator", "q_x"): "dimensionless",
    ("Resonator", "q_y"): "dimensionless",
    ("Resonator", "angular_gain"): "dimensionless",
    ("Resonator", "damping_coupling"): "rate constant",
    ("Resonator", "stiffness_coupling"): "stiffness per unit mass",
    ("Resonator", "duffing_x"): "cubic stiffness per unit mass",
    ("Resonator", "duffing_y"): "cubic stiffness per unit mass",
    ("Resonator", "tcf"): "temperature coefficient",
    ("Resonator", "tcq"): "temperature coefficient",
    ("Resonator", "tcf_split"): "temperature coefficient",
    ("Resonator", "t_ref"): "temperature",
    ("DriveElectrode", "force_per_volt"): "force per volt",
    ("FrontEnd", "current_per_velocity"): "current per velocity",
    ("FrontEnd", "gain"): "gain",
    ("FrontEnd", "adc_lsb"): "voltage",
    ("DriveLoop", "amplitude_setpoint"): "ADC word",
    ("DriveLoop", "center_frequency"): "angular frequency",
    ("DriveLoop", "pll_kp"): "rate constant",
    ("DriveLoop", "pll_ki"): "rate constant squared",
    ("DriveLoop", "agc_kp"): "AGC proportional gain",
    ("DriveLoop", "agc_ki"): "AGC integral gain",
    ("DriveLoop", "demod_cutoff"): "angular frequency",
    ("DriveLoop", "reference_phase"): "angle",
    ("DriveLoop", "agc_leak"): "rate constant",
    ("FeedbackElectrode", "k_vf"): "force per volt",
    ("FeedbackElectrode", "v_dc"): "voltage",
    ("FeedbackElectrode", "gap"): "length",
    ("FeedbackElectrode", "gap_fraction"): "dimensionless",
    ("FeedbackElectrode", "v_dc_tc"): "temperature coefficient",
    ("FTRExcitation", "amplifier_gain"): "dimensionless",
    ("FTRExcitation", "branch_gain_error_plus"): "dimensionless",
    ("FTRExcitation", "branch_gain_error_minus"): "dimensionless",
    ("DAC", "full_scale"): "voltage",
    ("DAC", "gain_error"): "dimensionless",
    ("DAC", "offset"): "voltage",
    ("DAC", "inl"): "ADC word",
    ("DAC", "dnl_amplitude"): "ADC word",
    ("DAC", "update_rate"): "frequency",
    ("RebalanceLoop", "kp"): "dimensionless",
    ("RebalanceLoop", "ki"): "rate constant",
    ("RebalanceLoop", "demod_cutoff"): "angular frequency",
    ("RebalanceLoop", "reference_phase"): "angle",
    ("RebalanceLoop", "carrier_phase"): "angle",
    ("RebalanceLoop", "leak"): "rate constant",
    ("OpenLoopReadout", "demod_cutoff"): "angular frequency",
    ("OpenLoopReadout", "reference_phase"): "angle",
    ("OpenLoopReadout", "phase_error"): "angle",
    ("VirtualCoriolisElectrode", "force_per_volt2"): "force per volt squared",
    ("ConstantTemperature", "value"): "temperature",
    ("WarmupTemperature", "ambient"): "temperature",
    ("WarmupTemperature", "rise"): "temperature difference",
    ("WarmupTemperature", "time_constant"): "time",
    ("PlateauTemperature", "plateaus_c"): "temperature",
    ("PlateauTemperature", "starts_s"): "time",
    ("PlateauTemperature", "initial_c"): "temperature",
    ("PlateauTemperature", "package_time_constant_s"): "time",
    ("PlateauTemperature", "rise_k"): "temperature difference",
    ("PlateauTemperature", "heating_time_constant_s"): "time",
}


def quantity_of(cls_name: str, field: str, frontend_kind: str | None = None) -> str:
    """The quantity of a leaf (a frontend's gain: a charge-amplifier gain or a transimpedance, by its kind)."""
    q = LEAF_QUANTITY[(cls_name, field)]
    if q == "gain":
        return "transimpedance" if frontend_kind == "transimpedance" else "charge-amplifier gain"
    return q


def canonical_unit(quantity: str) -> str:
    return next(iter(QUANTITIES[quantity]))


def factor_to_si(quantity: str, unit: str) -> float | None:
    """The factor from `unit` to the quantity's canonical unit, or None when the quantity does not take it."""
    return QUANTITIES[quantity].get(ALIASES.get(unit, unit))


def accepted_units(quantity: str) -> str:
    return ", ".join(repr(u) for u in QUANTITIES[quantity])
