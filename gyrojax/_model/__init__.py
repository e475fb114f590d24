"""What identification fits: named parameters and the `Model` (`parameters.py`), the data's padded arrays
(`fitdata.py`) and the weighted residuals of one device (`residuals.py`)."""
