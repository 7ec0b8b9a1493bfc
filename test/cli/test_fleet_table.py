"""The fleet table: every column typed and with its unit, failed bags as null rows."""

from flexlink_ros.cli.fleet_table import COLUMNS, TABLE_NAME, write_table
from flexlink_ros.names import JOINT_NAMES, OUTPUT_NAMES
import pandas as pd
import pyarrow.parquet as pq
import pytest


def test_written_rows_read_back_with_units_and_nulls(tmp_path):
    good = {'bag': 'a', 'per': 'revolution', 'index': 0, 'start_stamp_ns': 1, 'end_stamp_ns': 2,
            'samples': 2, 'estimated': 2, 'lever_tip_dx_p2p_um': 12.5, 'criterion_max_O4': 3.0,
            'skipped': 3, 'skipped_reasons': {'not a readable JointState': 3},
            'mechanism': '--mechanism cho1992', 'error': None, 'not_a_column': 'dropped'}
    failed = {'bag': 'b', 'per': 'revolution', 'index': -1, 'error': 'b is not an MCAP file'}
    path = write_table([good, failed], tmp_path)
    assert path == tmp_path / TABLE_NAME and sorted(p.name for p in tmp_path.iterdir()) == [
        TABLE_NAME]
    table = pq.read_table(path)
    assert table.column_names == [name for name, *_ in COLUMNS]
    units = {f.name: f.metadata[b'unit'].decode() for f in table.schema}
    assert all(units[f'{name}_p2p_um'] == 'um' for name in OUTPUT_NAMES)
    assert all(units[f'criterion_max_{j}'] == 'rad/(s N)' for j in JOINT_NAMES)
    assert units['start_stamp_ns'] == 'ns' and units['invalid_s'] == 's'
    frame = pd.read_parquet(path)
    assert frame['bag'].tolist() == ['a', 'b'] and frame['index'].tolist() == [0, -1]
    assert frame.loc[0, 'lever_tip_dx_p2p_um'] == 12.5
    assert frame.loc[0, 'skipped_reasons'] == [('not a readable JointState', 3)]
    assert pd.isna(frame.loc[1, 'samples']) and pd.isna(frame.loc[1, 'lever_tip_dx_p2p_um'])
    assert frame.loc[1, 'error'] == 'b is not an MCAP file' and pd.isna(frame.loc[0, 'error'])


def test_a_row_of_the_wrong_type_writes_nothing(tmp_path):
    with pytest.raises(Exception):   # pyarrow's conversion error
        write_table([{'bag': 'a', 'samples': 'many'}], tmp_path)
    assert list(tmp_path.iterdir()) == []
