"""
`flexlink report --out DIR`: every chart of the project in one directory with an index page.

Each chart module in :data:`SECTIONS` provides a function ``f(out_dir)`` returning either a
list of PNG paths or a dict ``{'charts': [...], 'text': 'markdown with the numbers'}``.
"""

import importlib
import inspect
import os
import pathlib
import time

from .main import emit
from .progress import Progress

# (title, module, function), in reading order.
SECTIONS = (
    ('Earles-Wu joint criteria and coil spring (Kang 1990)', 'flexlink_ros.report.criteria',
     'plot_criteria'),
    ('Transfer-matrix beam frequencies (Kim & Moon)', 'flexlink_ros.report.beam', 'plot_beam'),
    ('Flexible four-bar: frozen modes and response (Cho 1992)', 'flexlink_ros.report.flex',
     'plot_flex'),
    ('Streaming estimator: accuracy of each model configuration', 'flexlink_ros.report.estimator',
     'plot_estimator'),
)


def _section_progress(function, progress, done, total, title):
    """Give a section that reports its own steps (a ``progress`` argument) the report's."""
    if progress is None or 'progress' not in inspect.signature(function).parameters:
        return {}
    return {'progress': lambda step, steps, what: progress(
        done, total, f'{title}: {what} ({step}/{steps})')}


def write_report(out_dir, only=None, progress=None):
    """
    Write every section's charts and an index.md into out_dir.

    Parameters
    ----------
    out_dir : str or pathlib.Path
        Target directory (created).
    only : sequence of str or None
        Module names to include (default: all).
    progress : callable or None
        ``progress(done, total, what)`` before each section and at the end.

    Returns
    -------
    dict
        {'index': path, 'sections': [{'title', 'charts', 'seconds', 'error'}]}.

    """
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    lines = ['# flexlink_ros report', '']
    sections = []
    chosen = [s for s in SECTIONS if not only or s[1] in only]
    for title, module_name, function_name in chosen:
        if progress is not None:
            progress(len(sections), len(chosen), title)
        entry = {'title': title, 'charts': [], 'seconds': 0.0, 'error': None}
        start = time.perf_counter()
        try:
            function = getattr(importlib.import_module(module_name), function_name)
        except (ImportError, AttributeError) as exc:
            entry['error'] = f'not available in this checkout ({exc})'
        else:
            result = function(out, **_section_progress(function, progress, len(sections),
                                                       len(chosen), title))
            if isinstance(result, dict):
                entry['charts'] = [str(p) for p in result.get('charts', [])]
                entry['text'] = result.get('text', '')
            else:
                entry['charts'] = [str(p) for p in result]
        entry['seconds'] = time.perf_counter() - start
        sections.append(entry)
        lines += [f'## {title}', '']
        if entry['error']:
            lines += [f'_{entry["error"]}_', '']
            continue
        if entry.get('text'):
            lines += [entry['text'], '']
        for chart in entry['charts']:
            name = pathlib.Path(chart).name
            lines += [f'![{name}]({os.path.relpath(chart, out)})', '']
    if progress is not None:
        progress(len(sections), len(chosen), 'index')
    index = out / 'index.md'
    index.write_text('\n'.join(lines))
    return {'index': str(index), 'sections': sections}


def _report(args):
    with Progress('report', unit='section') as progress:
        result = write_report(args.out, progress=progress)
    text = [f'report: {result["index"]}']
    for entry in result['sections']:
        state = entry['error'] or f'{len(entry["charts"])} charts, {entry["seconds"]:.1f} s'
        text.append(f'  {entry["title"]}: {state}')
    return emit(result, '\n'.join(text), args.json)


def register(subparsers):
    """Add the `report` subcommand."""
    parser = subparsers.add_parser('report', help='write every chart and an index page')
    parser.add_argument('--out', default='out/report', help='output directory')
    parser.add_argument('--json', action='store_true', help='print one JSON object')
    parser.set_defaults(func=_report)
