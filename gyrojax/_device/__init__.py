"""A user's own device: device files (`file.py`, units in `units.py`), whether its loops can lock (`lock.py`), and
the checked start of a fit, the file against what the data reveal directly (`check.py`)."""
