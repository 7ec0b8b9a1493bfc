"""
The fleet table: ``summary.parquet``, one row per bag and period, each column with its unit.

The columns are fixed (:data:`COLUMNS`); a failed bag's row has its path, index -1 and the
reason in 'error', the rest null. Each field carries its unit in the Parquet field metadata
('unit'). pyarrow (which ``ray[data]`` brings) is imported when the table is written.
"""

import os
import pathlib

from ..names import JOINT_NAMES, OUTPUT_NAMES

TABLE_NAME = 'summary.parquet'
# (column, type, unit, meaning); type: 'str', 'int', 'float' or 'counts' ({reason: count}).
COLUMNS = (
    [('bag', 'str', '', 'the bag as given (file or directory)'),
     ('per', 'str', '', "the period: 'revolution' or 'minute'"),
     ('index', 'int', '', 'period number in the bag from 0 (-1: the bag failed)'),
     ('start_stamp_ns', 'int', 'ns', "the period's first sample stamp"),
     ('end_stamp_ns', 'int', 'ns', "the period's last sample stamp"),
     ('samples', 'int', '', 'usable crank samples'),
     ('estimated', 'int', '', 'samples with an estimate (the others: outliers, out of bound)')]
    + [(f'{name}_p2p_um', 'float', 'um', f'peak-to-peak of {name}') for name in OUTPUT_NAMES]
    + [(f'criterion_max_{joint}', 'float', 'rad/(s N)',
        f'largest Earles-Wu criterion |dgamma/dt|/R of joint {joint}') for joint in JOINT_NAMES]
    + [(f'criterion_angle_{joint}_rad', 'float', 'rad',
        f'crank angle in [0, 2 pi) where joint {joint} had it') for joint in JOINT_NAMES]
    + [('error_indicator_max', 'float', '', 'largest error indicator'),
       ('nonlinearity_max', 'float', '', 'largest nonlinearity (validity) indicator'),
       ('invalid_s', 'float', 's', 'time with the nonlinearity indicator above the threshold'),
       ('clipped_speed_s', 'float', 's', "time with the speed beyond the model's range"),
       ('outliers', 'int', '', "samples the estimator's input gate refused"),
       ('out_of_bound', 'int', '', "estimates beyond the model's deflection bound"),
       ('repeated', 'int', '', 'exact repeats of the previous sample'),
       ('skipped', 'int', '', 'messages that were not a usable sample'),
       ('skipped_reasons', 'counts', '', 'why they were skipped: {reason: count}'),
       ('mechanism', 'str', '', 'where the mechanism and model options came from'),
       ('error', 'str', '', 'why the bag failed (null: it did not)')])


def schema():
    """Build the pyarrow schema of the table (units in each field's metadata)."""
    import pyarrow as pa
    types = {'str': pa.string(), 'int': pa.int64(), 'float': pa.float64(),
             'counts': pa.map_(pa.string(), pa.int64())}
    return pa.schema([pa.field(name, types[kind], metadata={'unit': unit, 'meaning': meaning})
                      for name, kind, unit, meaning in COLUMNS])


def write_table(rows, directory):
    """
    Write the rows as ``directory/summary.parquet`` (whole or not at all).

    Parameters
    ----------
    rows : list of dict
        Table rows (missing keys are null; extra keys are left out).
    directory : str or os.PathLike
        Where to write.

    Returns
    -------
    pathlib.Path

    """
    import pyarrow as pa
    import pyarrow.parquet as pq
    names = [name for name, *_ in COLUMNS]
    cleaned = [{name: row.get(name) for name in names} for row in rows]
    for row in cleaned:
        if row['skipped_reasons'] is not None:
            row['skipped_reasons'] = list(row['skipped_reasons'].items())
    table = pa.Table.from_pylist(cleaned, schema=schema())
    path = pathlib.Path(directory) / TABLE_NAME
    partial = path.with_name(f'.{TABLE_NAME}.partial')
    pq.write_table(table, partial)
    os.replace(partial, path)
    return path
