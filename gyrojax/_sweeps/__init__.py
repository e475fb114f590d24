"""The sweep kinds of the data format: what each experiment applies, reads, simulates and fits.

`AbstractSweep` (`base.py`) is the interface; one file per kind (`rate_table.py`, `vcf_static.py`,
`vcf_dynamic.py`, `dac.py`, and the revealing experiments `quadrature_injection.py`, `drive_amplitude.py`,
`drive_frequency.py`, `setpoint_zero_rate.py`, `branch_voltages.py`), each with its points and settings as
fields, registered by name in `registry.py` (`SWEEP_KINDS`, the one list of kinds); `protocol.py` holds the
`Protocol` (the run timing every kind shares: warm-up, dwell, order, chamber plateaus; it knows no kind),
`lot_campaign.py` what a simulated campaign fixes, `steady.py` the settle that every steady sweep shares and
`setpoint.py` the one the AGC set-point sweeps share.
"""
