"""The benchmarks (and the studies one of their tests reads) import as top-level modules."""

import pathlib
import sys

REPO = pathlib.Path(__file__).resolve().parents[2]
sys.path[:0] = [str(REPO / 'benchmarks'), str(REPO / 'docs' / 'studies')]
