"""ament's own linters, with their own settings, over the package, tests, lab scripts, setup.py."""

import pathlib

from ament_flake8.main import main_with_errors
from ament_pep257.main import main as pep257_main
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
# Explicit paths: with none, the linters walk the working directory (.venv/ and build/ too).
PATHS = [str(ROOT / 'flexlink_ros'), str(ROOT / 'test'), str(ROOT / 'launch'),
         str(ROOT / 'benchmarks'), str(ROOT / 'docs' / 'studies'), str(ROOT / 'setup.py')]


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    rc, errors = main_with_errors(argv=PATHS)
    assert rc == 0, f'{len(errors)} flake8 findings:\n' + '\n'.join(errors)


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    assert pep257_main(argv=PATHS) == 0, 'pep257 findings (printed above)'
