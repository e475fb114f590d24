"""Revealing experiments: measurement models for the effects that rate-table, VCF and DAC sweeps cannot find.

One module per experiment, each with its settings (with provenance), its reading's noise and a `predict`
function on the steady tier (jit-friendly, differentiable with respect to the device's leaves):

- `drive_amplitude`: an AGC set-point sweep reading the drive frequency and the drive pick-off amplitude
  (`duffing_drive`, `agc_finite_gain`);
- `quadrature_injection`: a virtual-Coriolis force in phase with the drive displacement (`quadrature_phase`);
- `branch_voltages`: the AC voltages of the two push-pull feedback branches read apart (`pushpull_mismatch`);
- `temperature_plateaus`: rate-table and static-VCF sweeps at chamber plateaus within one run (`vref_drift`,
  `thermal_drift`, `zro_tempco`);
- `amplitude_rate_table`: a rate table at two drive amplitudes within one run, the stand-in for a mode
  reversal (`damping_coupling`).

`_absorb.py` measures what a baseline's free parameters leave of an effect's fingerprint on a reading.
"""
