"""
References a reader can follow: no issue numbers, and every module path named exists.

Read from the source (docstrings and comments of the Python files, the C sources, README.md and
docs/), no imports: an issue number means nothing to a reader of the repository (the finding
is said in words), and a path or dotted module name that no longer exists sends the reader
nowhere.
"""

import ast
import io as stdlib_io
import pathlib
import re
import tokenize

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGE = ROOT / 'flexlink_ros'
LAYERS = ('core', 'io', 'ros', 'cli', 'studies', 'report')
ISSUE_NUMBER = re.compile(r'\bissues? ?#?\d|(?<![\w&/])#\d{2}\b', re.IGNORECASE)
# Paths: in the package (with or without its name), or under the repository's folders.
PACKAGE_PATH = re.compile(
    r'(?<![\w./-])(?:flexlink_ros/)?((?:%s)/[\w/]*\w\.(?:py|c|h))\b' % '|'.join(LAYERS))
REPOSITORY_PATH = re.compile(
    r'(?<![\w./-])((?:test|benchmarks|docs|config|launch)/[\w./-]*\w)')
# Dotted module names: flexlink_ros.layer.module..., or layer.module... inside the package's
# own text (a docstring's "core.fe.linkage").
FILE_SUFFIXES = ('md', 'py', 'c', 'h', 'yaml', 'txt', 'rst')
DOTTED = re.compile(r'(?<![\w.])((?:flexlink_ros\.)?(?:%s)(?:\.\w+)+)' % '|'.join(LAYERS))


def python_text(path):
    """Docstrings and comments of a Python file (not its string literals: paths built at run)."""
    source = path.read_text('utf-8')
    parts = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            docstring = ast.get_docstring(node, clean=False)
            if docstring:
                parts.append(docstring)
    for token in tokenize.generate_tokens(stdlib_io.StringIO(source).readline):
        if token.type == tokenize.COMMENT:
            parts.append(token.string)
    return '\n'.join(parts)


def sources():
    """(path, the text a reader reads) of every file whose references are checked."""
    found = []
    for folder in (PACKAGE, ROOT / 'test', ROOT / 'benchmarks', ROOT / 'docs'):
        for path in sorted(folder.rglob('*')):
            if '.venv' in path.parts or not path.is_file():
                continue
            if path.suffix == '.py':
                found.append((path, python_text(path)))
            elif path.suffix in ('.md', '.c', '.h'):
                found.append((path, path.read_text('utf-8')))
    found.append((ROOT / 'README.md', (ROOT / 'README.md').read_text('utf-8')))
    return found


def module_defines(path, name):
    """Tell whether the Python file ``path`` defines ``name`` at its top level or in a class."""
    text = path.read_text('utf-8')
    return re.search(r'^\s*(?:def|class)\s+%s\b|^\s*%s\b\s*[:=]|import[^\n]*\b%s\b'
                     % ((re.escape(name),) * 3), text, re.MULTILINE) is not None


def dotted_exists(dotted):
    """Resolve ``[flexlink_ros.]layer.module[.name]``: its modules exist, its name is defined."""
    parts = dotted.split('.')
    if parts[0] == 'flexlink_ros':
        parts = parts[1:]
    folder = PACKAGE
    for k, part in enumerate(parts):
        if (folder / part).is_dir():
            folder = folder / part
            continue
        module = folder / f'{part}.py'
        if module.is_file():
            rest = parts[k + 1:]
            return not rest or module_defines(module, rest[0])
        if (folder / f'{part}.c').is_file() or (folder / f'_{part}.c').is_file():
            return True
        # A package followed by a name: defined in its __init__, or not a module path at all.
        return k > 1 and module_defines(folder / '__init__.py', part)
    return True


def stdlib_io_name(dotted):
    """Tell whether a dotted name is the standard library's io (io.BytesIO), not the package's."""
    parts = dotted.split('.')
    return parts[0] == 'io' and hasattr(stdlib_io, parts[1])


def missing_references(text):
    """Return the module paths and dotted names in ``text`` that do not exist."""
    missing = set()
    for match in PACKAGE_PATH.finditer(text):
        if not (PACKAGE / match.group(1)).exists():
            missing.add(match.group(0))
    for match in REPOSITORY_PATH.finditer(text):
        path = match.group(1).rstrip('.')
        if '.' in pathlib.PurePath(path).name and not (ROOT / path).exists():
            missing.add(path)
    for match in DOTTED.finditer(text):
        dotted = match.group(1).rstrip('.')
        if dotted.rsplit('.', 1)[1] in FILE_SUFFIXES:   # a file (docs' cli.md), not a module
            continue
        if not stdlib_io_name(dotted) and not dotted_exists(dotted):
            missing.add(dotted)
    return sorted(missing)


SOURCES = sources()
IDS = [str(path.relative_to(ROOT)) for path, _ in SOURCES]


@pytest.mark.parametrize('path, text', SOURCES, ids=IDS)
def test_no_issue_numbers(path, text):
    assert [line.strip() for line in text.splitlines() if ISSUE_NUMBER.search(line)] == []


@pytest.mark.parametrize('path, text', SOURCES, ids=IDS)
def test_every_module_path_named_exists(path, text):
    assert missing_references(text) == []


def test_the_checks_see_what_they_forbid():
    assert ISSUE_NUMBER.search('a finding (issue 14, item 2)')
    assert ISSUE_NUMBER.search('targets (#15)') and ISSUE_NUMBER.search('Issue #3 says')
    assert not ISSUE_NUMBER.search('the issue at hand; &#39; 0x#12 colour #fff')
    assert missing_references(
        'see core/fe/simulate.py, flexlink_ros/core/simulate.py, core.assembly, '
        ':func:`flexlink_ros.core.fe.simulate.no_such_function`, test/core/test_gone.py '
        'and docs/gone.md; io.BytesIO is the standard library') == sorted([
            'flexlink_ros.core.fe.simulate.no_such_function', 'core.assembly',
            'flexlink_ros/core/simulate.py', 'docs/gone.md', 'test/core/test_gone.py'])
    assert missing_references('core/fe/simulate.py, core.fe.simulate.periodic_response, '
                              'flexlink_ros.io.recorder.McapRecorder.enqueue') == []
