"""`flexlink report` writes an index page naming every section, charts or not."""

import json

from flexlink_ros.cli import main as cli, report as cli_report


def test_report_index_lists_every_section(tmp_path, capsys):
    modules = [module for _, module, _ in cli_report.SECTIONS]
    assert cli.main(['report', '--out', str(tmp_path), '--json']) == 0
    captured = capsys.readouterr()
    result = json.loads(captured.out)    # one JSON object: the progress is on stderr
    assert captured.err.strip().splitlines()[-1].startswith(
        f'report: 100% {len(modules)}/{len(modules)} [')
    index = (tmp_path / 'index.md').read_text()
    assert len(result['sections']) == len(modules)
    for entry in result['sections']:
        assert f'## {entry["title"]}' in index
        for chart in entry['charts']:
            assert (tmp_path / chart).exists() or __import__('os').path.exists(chart)
