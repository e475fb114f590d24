"""The sweep kinds of the data format: what each experiment applies, reads, simulates and fits.

`AbstractSweep` (`base.py`) is the interface; one file per kind (`rate_table.py`, `vcf_static.py`,
`vcf_dynamic.py`, `dac.py`), registered by name in `registry.py`; `protocol.py` holds the `Protocol` (inputs,
timing, order, warm-up) and `steady.py` the settle that every steady sweep shares.
"""
