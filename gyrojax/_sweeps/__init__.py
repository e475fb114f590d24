"""The sweep kinds of the data format: what each experiment applies, reads, simulates and fits.

`AbstractSweep` (`base.py`) is the interface; one file per kind (`rate_table.py`, `vcf_static.py`,
`vcf_dynamic.py`, `dac.py`, and the revealing experiments `quadrature_injection.py`, `drive_amplitude.py`,
`drive_frequency.py`, `setpoint_zero_rate.py`, `branch_voltages.py`), registered by name in `registry.py`;
`protocol.py` holds the `Protocol` (inputs, timing, order, warm-up, chamber plateaus), `steady.py` the settle
that every steady sweep shares and `setpoint.py` the one the AGC set-point sweeps share.
"""
