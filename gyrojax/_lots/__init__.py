"""Simulated lots: the lot PyTree and its padding (`stack.py`), process-level spreads (`process.py`), run noise
(`noise.py`) and simulated measurement campaigns (`campaign.py`)."""
