"""
The package's shape, checked from its source with ast (no imports, under a second).

Modules up to 600 lines (one concept each, not cut at a line count), functions up to 60 lines
of code (docstrings not counted), imports that go one way between layers and form no cycle,
no imports hidden inside functions except the optional heavy ones in command handlers, a
core free of ROS, MCAP and matplotlib, and private names (``_x``) private to their module: no
class split across modules through another module's private attributes.
"""

import ast
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGE = ROOT / 'flexlink_ros'
MODULE_LINES = 600
FUNCTION_LINES = 60
# Which layers each layer may import (names and errors are importable from everywhere).
LAYERS = {
    'core': {'core'},
    'studies': {'core', 'studies'},
    'report': {'core', 'studies', 'report'},
    'io': {'core', 'io'},
    'ros': {'core', 'io', 'ros'},
    'cli': {'core', 'studies', 'report', 'io', 'ros', 'cli'},
    'names': set(),
    'errors': set(),
    '__init__': set(),
}
# Inside the core: the FE model knows nothing of reductions, a reduction nothing of estimators.
CORE_FORBIDDEN = {'fe': {'reduction', 'estimation'}, 'tmm': {'reduction', 'estimation'},
                  'reduction': {'estimation'}}
NOT_IN_CORE = ('rclpy', 'rosidl', 'ament_index_python', 'mcap', 'matplotlib', 'builtin_interfaces',
               'std_msgs', 'sensor_msgs', 'geometry_msgs', 'visualization_msgs',
               'diagnostic_msgs', 'rcl_interfaces', 'lifecycle_msgs')
# Private attributes read from another module that stay, each with its reason.
PRIVATE_REACH_ALLOWED = {
    ('cli/fleet.py', '_actions'): 'argparse has no public accessor of an added argument',
    ('cli/replay_model.py', '_actions'): 'argparse has no public accessor of an added argument',
    ('cli/replay_split.py', '_exit'): 'a forked child ends without the exit handlers and '
                                      'buffered output it shares with its parent',
}
# Modules still split from their class through private attributes (to shrink): the node's
# EstimatorNode is a mixin of the two node classes and itself has the recording as a mixin.
PRIVATE_REACH_TO_SHRINK = {'ros/node.py', 'ros/node_recording.py', 'ros/estimator_node.py'}
# Optional heavy dependencies a command handler may import when it runs.
LATE_IMPORTS = ('rclpy', 'matplotlib', 'exudyn', 'ray', 'pyarrow')
LATE_IMPORT_LAYERS = ('cli', 'ros', 'studies', 'report')


def modules():
    return sorted(p for p in PACKAGE.rglob('*.py'))


def module_name(path):
    parts = path.relative_to(ROOT).with_suffix('').parts
    return '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)


def layer_of(name):
    parts = name.split('.')
    return parts[1] if len(parts) > 1 else '__init__'


def imported_modules(path):
    """(absolute module, line, inside a function) of every import in ``path``."""
    tree = ast.parse(path.read_text('utf-8'))
    package = module_name(path).split('.')
    if path.name != '__init__.py':
        package = package[:-1]
    found = []

    def visit(node, in_function):
        for child in ast.iter_child_nodes(node):
            inner = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef))
            if isinstance(child, ast.Import):
                found.extend((alias.name, child.lineno, in_function) for alias in child.names)
            elif isinstance(child, ast.ImportFrom):
                base = child.module or ''
                if child.level:
                    base = '.'.join(package[:len(package) - child.level + 1]
                                    + ([base] if base else []))
                found.append((base, child.lineno, in_function))
                for alias in child.names:   # `from . import module`
                    if (PACKAGE.parent / (base + '.' + alias.name).replace('.', '/')).with_suffix(
                            '.py').exists():
                        found.append((f'{base}.{alias.name}', child.lineno, in_function))
            visit(child, inner)

    visit(tree, False)
    return found


def function_sizes(path):
    """(qualified name, lines of code without the docstring) of every function."""
    tree = ast.parse(path.read_text('utf-8'))
    sizes = []

    def visit(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = child.end_lineno - child.lineno + 1
                body = child.body
                if body and isinstance(body[0], ast.Expr) and isinstance(
                        getattr(body[0], 'value', None), ast.Constant) and isinstance(
                        body[0].value.value, str):
                    lines -= body[0].end_lineno - body[0].lineno + 1
                sizes.append((prefix + child.name, lines))
                visit(child, prefix + child.name + '.')
            elif isinstance(child, ast.ClassDef):
                visit(child, prefix + child.name + '.')

    visit(tree, '')
    return sizes


def is_private(name):
    return name.startswith('_') and not (name.startswith('__') and name.endswith('__'))


def private_reaches(path):
    """
    (line, expression) of every private attribute ``_x`` used in ``path`` but defined elsewhere.

    A module defines a name by a ``def`` or ``class``, an assignment to a name (module or class
    body) or an assignment to ``self._x`` / ``cls._x``. Using ``obj._x`` (``self`` included)
    where the module does not define ``_x`` reaches into another module's class: a mixin over
    its host's attributes, a subclass on its base's internals, a function on another's object.
    """
    tree = ast.parse(path.read_text('utf-8'))
    defined = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            defined.add(node.name)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            defined.add(node.id)
        elif (isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store)
              and isinstance(node.value, ast.Name) and node.value.id in ('self', 'cls')):
            defined.add(node.attr)
    return sorted((node.lineno, ast.unparse(node)) for node in ast.walk(tree)
                  if isinstance(node, ast.Attribute) and is_private(node.attr)
                  and node.attr not in defined)


MODULES = modules()
IDS = [str(p.relative_to(PACKAGE)) for p in MODULES]


@pytest.mark.parametrize('path', MODULES, ids=IDS)
def test_module_size(path):
    lines = len(path.read_text('utf-8').splitlines())
    assert lines <= MODULE_LINES, f'{path.name}: {lines} lines'


@pytest.mark.parametrize('path', MODULES, ids=IDS)
def test_function_sizes(path):
    long = [(name, lines) for name, lines in function_sizes(path) if lines > FUNCTION_LINES]
    assert long == []


@pytest.mark.parametrize('path', MODULES, ids=IDS)
def test_imports_go_one_way(path):
    name = module_name(path)
    layer = layer_of(name)
    allowed = LAYERS[layer] | {'names', 'errors'}
    if layer == '__init__':
        allowed = allowed | {'__init__'}
    wrong = []
    for target, line, _ in imported_modules(path):
        if target == 'flexlink_ros' or not target.startswith('flexlink_ros.'):
            continue
        target_layer = layer_of(target)
        if target_layer not in allowed:
            wrong.append(f'{line}: {layer} imports {target}')
        if layer == 'core' and target_layer == 'core':
            mine, theirs = name.split('.')[2:3], target.split('.')[2:3]
            if mine and theirs and theirs[0] in CORE_FORBIDDEN.get(mine[0], ()):
                wrong.append(f'{line}: core.{mine[0]} imports {target}')
    assert wrong == []


@pytest.mark.parametrize('path', MODULES, ids=IDS)
def test_no_imports_inside_functions(path):
    layer = layer_of(module_name(path))
    hidden = [f'{line}: {target}' for target, line, inside in imported_modules(path)
              if inside and not (layer in LATE_IMPORT_LAYERS
                                 and target.split('.')[0] in LATE_IMPORTS)]
    assert hidden == []


CORE = [(p, i) for p, i in zip(MODULES, IDS) if layer_of(module_name(p)) == 'core']


@pytest.mark.parametrize('path', [p for p, _ in CORE], ids=[i for _, i in CORE])
def test_core_imports_no_ros(path):
    ros = [f'{line}: {target}' for target, line, _ in imported_modules(path)
           if target.split('.')[0] in NOT_IN_CORE or target.split('.')[0].endswith('_msgs')]
    assert ros == []


def test_no_import_cycles():
    graph = {module_name(p): {t for t, _, inside in imported_modules(p)
                              if not inside and t.startswith('flexlink_ros.')}
             for p in MODULES}
    graph = {m: {t for t in targets if t in graph and t != m} for m, targets in graph.items()}
    cycles = strongly_connected(graph)
    assert [sorted(c) for c in cycles if len(c) > 1] == []


def strongly_connected(graph):
    """Tarjan's strongly connected components of ``graph`` (dict: node -> set of nodes)."""
    index, low, stack, on_stack, out = {}, {}, [], set(), []

    def connect(node):
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for succ in graph[node]:
            if succ not in index:
                connect(succ)
                low[node] = min(low[node], low[succ])
            elif succ in on_stack:
                low[node] = min(low[node], index[succ])
        if low[node] == index[node]:
            component = set()
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.add(member)
                if member == node:
                    break
            out.append(component)

    for node in graph:
        if node not in index:
            connect(node)
    return out


@pytest.mark.parametrize('path', MODULES, ids=IDS)
def test_no_private_attributes_of_another_module(path):
    relative = str(path.relative_to(PACKAGE))
    reached = [(line, text) for line, text in private_reaches(path)
               if (relative, '_' + text.rsplit('._', 1)[1]) not in PRIVATE_REACH_ALLOWED]
    if relative in PRIVATE_REACH_TO_SHRINK:
        assert reached, f'{relative} no longer reaches: take it off PRIVATE_REACH_TO_SHRINK'
    else:
        assert reached == []


def test_the_checks_see_what_they_forbid(tmp_path):
    sample = PACKAGE / 'core' / '_layout_probe.py'
    sample.write_text('import rclpy\n\n\ndef f():\n    from ..ros import node\n'
                      + '    x = 1\n' * 70)
    try:
        assert any(t == 'rclpy' for t, _, _ in imported_modules(sample))
        assert ('flexlink_ros.ros', 5, True) in imported_modules(sample)
        assert function_sizes(sample) == [('f', 72)]   # def, import and 70 lines
    finally:
        sample.unlink()
    sample.write_text('class Mixin:\n    def f(self, other):\n        self._own = other._theirs\n'
                      '        return self._host, self._own, Mixin._g\n\n    def _g(self):\n'
                      '        pass\n')
    try:
        assert private_reaches(sample) == [(3, 'other._theirs'), (4, 'self._host')]
    finally:
        sample.unlink()
    assert strongly_connected({'a': {'b'}, 'b': {'a'}, 'c': set()}) in (
        [{'a', 'b'}, {'c'}], [{'c'}, {'a', 'b'}])


def mirrored_tests(path):
    """Return the test files that may hold ``path``'s tests: its mirror or the layer-named one."""
    relative = path.relative_to(PACKAGE)
    folder = ROOT / 'test' / relative.parent
    names = [f'test_{path.stem}.py']
    if relative.parent.parts:
        names.append(f'test_{relative.parts[0]}_{path.stem}.py')
    return [folder / name for name in names]


# Modules still tested only from the test file of a module that uses them (to shrink).
WITHOUT_OWN_TEST_FILE = {
    'cli/demo_summary.py',
    'cli/mcap_record.py',
    'ros/message_outcomes.py',
    'ros/node_model.py',
    'ros/startup.py',
}


TESTED = [(p, i) for p, i in zip(MODULES, IDS) if p.name not in ('__init__.py', '__main__.py')]


@pytest.mark.parametrize('path', [p for p, _ in TESTED], ids=[i for _, i in TESTED])
def test_every_module_has_its_test_file(path):
    relative = str(path.relative_to(PACKAGE))
    has_file = any(candidate.is_file() for candidate in mirrored_tests(path))
    if relative in WITHOUT_OWN_TEST_FILE:
        assert not has_file, f'{relative} has its test file now: take it off the list'
    else:
        assert has_file, [str(c.relative_to(ROOT)) for c in mirrored_tests(path)]


def test_test_file_names_are_unique():
    names = [p.name for p in (ROOT / 'test').rglob('test_*.py')]
    assert sorted(n for n in set(names) if names.count(n) > 1) == []
