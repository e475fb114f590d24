"""Input and output: results written in an output format (`write_result`, `FORMATS`, `register_format`, the contracts
`AbstractResult` and `AbstractFormat`), the table files (`read_table`/`write_table`, the column lists, the DAC word
decoding, the aggregation of raw samples, the padded `SweepArrays` and a fit's `FitData` of one per sweep kind),
fits and device files, the atomic writes every output goes through, and the persistent compilation cache.

This module only re-exports; the code lives in the private modules it imports from.
"""

from ._compile.cache import compilation_cache as compilation_cache
from ._data.arrays import SweepArrays as SweepArrays
from ._data.cells import (
    DAC_WORD_BITS as DAC_WORD_BITS,
    OPTIONAL_COLUMNS as OPTIONAL_COLUMNS,
    REQUIRED_COLUMNS as REQUIRED_COLUMNS,
    decode_dac_word as decode_dac_word,
)
from ._data.files import read_table as read_table, write_table as write_table
from ._data.io import (
    atomic_directory as atomic_directory,
    atomic_write_bytes as atomic_write_bytes,
    atomic_write_json as atomic_write_json,
)
from ._data.samples import aggregate_samples as aggregate_samples
from ._device.file import load_device as load_device
from ._identify.fitio import load_fit as load_fit, save_fit as save_fit
from ._model.fitdata import FitData as FitData
from ._report import (
    FORMATS as FORMATS,
    AbstractFormat as AbstractFormat,
    AbstractResult as AbstractResult,
    register_format as register_format,
    write_result as write_result,
)


__all__ = [
    "AbstractFormat",
    "AbstractResult",
    "DAC_WORD_BITS",
    "FORMATS",
    "FitData",
    "OPTIONAL_COLUMNS",
    "REQUIRED_COLUMNS",
    "SweepArrays",
    "aggregate_samples",
    "atomic_directory",
    "atomic_write_bytes",
    "atomic_write_json",
    "compilation_cache",
    "decode_dac_word",
    "load_device",
    "load_fit",
    "read_table",
    "register_format",
    "save_fit",
    "write_result",
    "write_table",
]
