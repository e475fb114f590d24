"""Compilation: gyrojax's programs jitted with its XLA:CPU options (`jit.py`), the persistent compilation
cache (`cache.py`) and identify's largest programs exported to disk (`export.py`, with their key in
`program_key.py` and their stored form in `artifact.py`)."""
