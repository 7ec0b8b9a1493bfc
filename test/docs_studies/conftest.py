"""The studies (and the benchmarks' timers they use) import as top-level modules."""

import pathlib
import sys

REPO = pathlib.Path(__file__).resolve().parents[2]
sys.path[:0] = [str(REPO / 'docs' / 'studies'), str(REPO / 'benchmarks')]
