"""Recordings as labs hold them: ``.mat`` (v4-v7 and v7.3), HDF5 and CSV/TSV files with the
lab's own column names, read through a column map into a
:class:`~hcard.calibration.measurement.Measurement` (spec/lab-recordings.md).

Modules: :mod:`column_map` (the map file), :mod:`detect` (the file's type), :mod:`mat_files`,
:mod:`hdf5_files`, :mod:`delimited` (the readers), :mod:`assemble` (map applied: units, gain,
offset, counters, time base, derived columns, labels), :mod:`reading` (the one entry point,
:func:`read_recording`), :mod:`propose` (``hcard calibrate map``).
"""
