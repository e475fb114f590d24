"""Measured data: cells and `DataError`, the `Table`, its file formats, its padded array form and the reduction
of raw samples to settled points (the tidy format of docs/data_format.md)."""
