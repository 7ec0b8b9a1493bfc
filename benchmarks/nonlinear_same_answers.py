"""
The reduced nonlinear model's answers from this tree against another build's, on the bench signals.

    .venv/bin/python benchmarks/nonlinear_same_answers.py --reference-root TREE \
        [--reference-python TREE/.venv/bin/python] [--seconds 3]

Each tree estimates the same signals in its own process (``estimate_nonlinear``, the compiled
step where built; the model from one shared cache): the bench's 391 rpm at 1 kHz, the same with
+-30 % jitter in the sample times, and 365 and 420 rpm. Prints per signal the largest
difference of the outputs, axial forces and link slopes as a fraction of their range, the
converged samples and the Newton iterations of both; exits 1 if an output differs by more
than ``--limit`` of its range or the converged samples differ.
"""

import argparse
import json
import pathlib
import subprocess
import sys
import tempfile

ROOT = pathlib.Path(__file__).resolve().parents[1]
SIGNALS = (('391 rpm', 391.0, 0.0), ('391 rpm, 30 % jitter', 391.0, 0.3),
           ('365 rpm', 365.0, 0.0), ('420 rpm', 420.0, 0.0))
FIELDS = ('outputs', 'axial_force', 'link_slope')


def run_one(root, seconds, cache, out_path):
    """Estimate every signal with the tree at ``root``; save the arrays to ``out_path``."""
    sys.path.insert(0, str(root))
    from flexlink_ros.core.estimation.nonlinear_stream import estimate_nonlinear
    from flexlink_ros.core.mechanism_file import load_mechanism
    from flexlink_ros.core.options import ModelOptions
    from flexlink_ros.core.reduction.nonlinear_model import nonlinear_model_for
    from flexlink_ros.studies.synthetic import synthetic_signal
    import numpy as np
    options = ModelOptions(rigid_crank=True, bearings='flexible', elements_per_link=8,
                           stiffness_damping=1e-4)
    tables, _ = nonlinear_model_for(load_mechanism('cho1992'), options, cache_dir=cache)
    arrays, iterations = {}, {}
    for index, (_, rpm, jitter) in enumerate(SIGNALS):
        stamps, angles, speeds = synthetic_signal(rpm, seconds, 1000.0, jitter=jitter,
                                                  seed=index)
        out = estimate_nonlinear(tables, stamps, angles, speeds)
        for name in FIELDS + ('converged',):
            arrays[f'{index}_{name}'] = out[name]
        iterations[str(index)] = int(out['newton_iterations'])
    np.savez(out_path, **arrays)
    print(json.dumps(iterations))


def compare(paths, iterations, limit):
    """Print the differences; return True if every signal's answers agree within ``limit``."""
    import numpy as np
    mine, theirs = (np.load(path) for path in paths)
    agree = True
    for index, (label, _, _) in enumerate(SIGNALS):
        parts = []
        for name in FIELDS:
            a, b = mine[f'{index}_{name}'], theirs[f'{index}_{name}']
            span = np.nanmax(b, axis=0) - np.nanmin(b, axis=0)
            relative = np.nanmax(np.abs(a - b), axis=0) / np.where(span > 0, span, 1.0)
            parts.append(f'{name} {relative.max():.1e}')
            if name == 'outputs':
                agree &= bool(relative.max() <= limit)
        same = bool(np.array_equal(mine[f'{index}_converged'], theirs[f'{index}_converged']))
        agree &= same
        verdict, joined = ('same' if same else 'DIFFERENT'), ', '.join(parts)
        here, there = iterations[0][str(index)], iterations[1][str(index)]
        print(f'{label:22s}: largest difference / range: {joined}; converged {verdict}; '
              f'Newton iterations {here} here, {there} reference')
    return agree


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--reference-root', help='the other tree (with its .venv)')
    parser.add_argument('--reference-python', default=None)
    parser.add_argument('--seconds', type=float, default=3.0)
    parser.add_argument('--limit', type=float, default=1e-9)
    parser.add_argument('--one', nargs=2, help=argparse.SUPPRESS)      # root, output path
    parser.add_argument('--cache-dir', default=None)
    args = parser.parse_args()
    if args.one:
        run_one(pathlib.Path(args.one[0]), args.seconds, args.cache_dir, args.one[1])
        return
    if not args.reference_root:
        parser.error('--reference-root is required')
    reference = pathlib.Path(args.reference_root).resolve()
    python = args.reference_python or str(reference / '.venv' / 'bin' / 'python')
    work = pathlib.Path(tempfile.mkdtemp(prefix='nonlinear-answers-'))
    cache = args.cache_dir or str(work / 'cache')
    paths, iterations = [work / 'here.npz', work / 'reference.npz'], []
    for executable, root, path in ((sys.executable, ROOT, paths[0]),
                                   (python, reference, paths[1])):
        out = subprocess.run([executable, __file__, '--one', str(root), str(path),
                              '--seconds', str(args.seconds), '--cache-dir', cache],
                             capture_output=True, text=True, check=True)
        iterations.append(json.loads(out.stdout.strip().splitlines()[-1]))
    sys.exit(0 if compare(paths, iterations, args.limit) else 1)


if __name__ == '__main__':
    main()
