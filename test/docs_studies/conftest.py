"""The studies import as top-level modules: ``docs/studies/`` (and the timers they use in
``benchmarks/``) are not packages."""

import pathlib
import sys

REPO = pathlib.Path(__file__).resolve().parents[2]
sys.path[:0] = [str(REPO / 'docs' / 'studies'), str(REPO / 'benchmarks')]
