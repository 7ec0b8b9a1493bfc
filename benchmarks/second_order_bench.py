"""
Time the factored second-order step compiled, per sample.

The step is FactoredForms (docs/studies/second_order_forms.py). A small C kernel (compiled here
with ``cc -O3``, the flags of the package's compiled step, setup.py) does per sample what a
compiled estimator step would add: the cubic-spline tables of cos/sin of the link angles and of
kappa (22 scalars), the rows of V q the links read, the rotation of the end-node translations,
the bands of G and the 4 x 4 output combination. It is checked against
:func:`second_order_forms.factored_second_order` at the grid angles (where the spline equals
its samples) before it is timed. Needs a C compiler; nothing here is used by the package at run
time.

:func:`streaming_overhead` times what the second order costs in the package's own compiled
step (core/estimation/_radau_step.c): the in-process streaming update and the batched step
of an order-1 and an order-2 model of the same options, in alternating rounds, medians.
``python benchmarks/second_order_bench.py`` prints both for the node's default
model and the rigid-crank ones.
"""

import argparse
import ctypes
import dataclasses
import json
import math
import pathlib
import shutil
import subprocess
import sys
import tempfile
import time

from flexlink_ros.core.estimation.streaming import StreamingEstimator
from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.fe.second_order_full import link_forms
from flexlink_ros.core.fe.second_order_geometry import output_coefficients
from flexlink_ros.core.fe.second_order_reduced import gather_harmonics
from flexlink_ros.core.kinematics import solve_kinematics
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction.cells import periodic_cell_coefficients
from flexlink_ros.core.reduction.mechanism_model import fe_mechanism, model_for_mechanism
import numpy as np

# The factored forms this kernel evaluates live with the second-order study, beside this folder.
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / 'docs' / 'studies'))
from second_order_forms import factored_forms, factored_second_order  # noqa: E402, I100
from update_bench import update_round  # noqa: E402, I100

SCALARS = 22    # cos, sin of the three link angles, then kappa (4 x 4), per grid node
GRID = 128

KERNEL = r"""
#include <math.h>
#include <time.h>
#define SCALARS 22
static void one(int r, int m, const double *vsel, const int *rows, int nslot,
                const int *kind, const int *i0, const int *i1, const int *slot_link,
                int nforms, const int *grows, const int *gptr, const int *gcol, const double *gval,
                const int *form_first, int cells, const double *table, const double *q,
                double theta, double *y, double *z, double *out)
{
    const double two_pi = 6.283185307179586;
    double x = fmod(theta, two_pi); if (x < 0) x += two_pi;
    x *= cells / two_pi;
    int k = (int)x; if (k >= cells) k = cells - 1;
    double t = x - k, w[4] = {1.0, t, t * t, t * t * t}, sc[SCALARS];
    const double *cell = table + (long)k * 4 * SCALARS;
    for (int j = 0; j < SCALARS; j++)
        sc[j] = w[0] * cell[j] + w[1] * cell[SCALARS + j] + w[2] * cell[2 * SCALARS + j]
              + w[3] * cell[3 * SCALARS + j];
    for (int i = 0; i < m; i++) {
        const double *row = vsel + (long)i * r; double acc = 0.0;
        for (int j = 0; j < r; j++) acc += row[j] * q[j];
        y[rows[i]] = acc;
    }
    for (int a = 0; a < nslot; a++) {
        int l = slot_link[a];
        if (kind[a] == 1) z[a] = y[i0[a]];
        else if (kind[a] == 2) z[a] = sc[2 * l] * y[i1[a]] - sc[2 * l + 1] * y[i0[a]];
        else z[a] = 0.0;
    }
    double s[4] = {0.0, 0.0, 0.0, 0.0};
    for (int f = 0; f < nforms; f++) {
        const double *zf = z + form_first[f]; const int *ptr = gptr + f * 65;
        double acc = 0.0;
        for (int row = 0; row < grows[f]; row++) {
            double inner = 0.0;
            for (int p = ptr[row]; p < ptr[row + 1]; p++) inner += gval[p] * zf[gcol[p]];
            acc += zf[row] * inner;
        }
        s[f] = 0.5 * acc;
    }
    for (int o = 0; o < 4; o++)
        out[o] = sc[6 + 4 * o] * s[0] + sc[7 + 4 * o] * s[1] + sc[8 + 4 * o] * s[2]
               + sc[9 + 4 * o] * s[3];
}

double run(int samples, int repeat, int r, int m, const double *vsel, const int *rows,
           int nslot, const int *kind, const int *i0, const int *i1, const int *slot_link,
           int nforms, const int *grows, const int *gptr, const int *gcol, const double *gval,
           const int *form_first, int cells, const double *table, const double *qs,
           const double *thetas, double *y, double *z, double *outs)
{
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    for (int rep = 0; rep < repeat; rep++)
        for (int i = 0; i < samples; i++)
            one(r, m, vsel, rows, nslot, kind, i0, i1, slot_link, nforms, grows, gptr, gcol, gval,
                form_first, cells, table, qs + (long)i * r, thetas[i], y, z, outs + 4L * i);
    clock_gettime(CLOCK_MONOTONIC, &t1);
    return ((t1.tv_sec - t0.tv_sec) * 1e9 + (t1.tv_nsec - t0.tv_nsec))
           / ((double)samples * repeat);
}
"""


def _compile(directory):
    compiler = shutil.which('cc') or shutil.which('gcc')
    if compiler is None:
        raise RuntimeError('no C compiler (cc) on PATH')
    source = pathlib.Path(directory) / 'second_order_kernel.c'
    library = pathlib.Path(directory) / 'second_order_kernel.so'
    source.write_text(KERNEL)
    subprocess.run([compiler, '-O3', '-shared', '-fPIC', str(source), '-o', str(library),
                    '-lm'], check=True, capture_output=True)
    return ctypes.CDLL(str(library))


def kernel_data(linkage, basis, grid=GRID):
    """Flat arrays of the kernel: rows of V, slot maps, CSR bands of G, spline tables."""
    forms = link_forms(linkage)
    used = sorted({int(i) for link in linkage.links
                   for i in np.flatnonzero(np.abs(gather_harmonics(linkage, link))
                                           .sum(axis=(0, 1)))})
    where = {dof: k for k, dof in enumerate(used)}
    kind, i0, i1, slot_link, first = [], [], [], [], {}
    for link in linkage.links:
        pieces = gather_harmonics(linkage, link)
        first[link] = len(kind)
        for a in range(pieces.shape[1]):
            if a % 3 == 0:
                continue
            t0, tc, ts = pieces[:, a]
            slot_link.append(link)
            if np.any(t0):
                kind.append(1), i0.append(where[int(np.flatnonzero(t0)[0])]), i1.append(0)
            elif np.any(tc):      # v = cos Y - sin X: i1 = Y (Tc = +1), i0 = X (Ts = -1)
                kind.append(2), i1.append(where[int(np.flatnonzero(tc)[0])])
                i0.append(where[int(np.flatnonzero(ts)[0])])
            else:
                kind.append(0), i0.append(0), i1.append(0)
    gptr = np.zeros((4, 65), dtype=np.int32)
    gcol, gval, form_first, grows = [], [], [], []
    for f, link in enumerate((0, 1, 2, 1)):
        form_first.append(first.get(link, 0))
        if link not in linkage.links:
            grows.append(0)
            continue
        gmatrix = forms.coupler_half if f == 3 else forms.full[link]
        keep = [a for a in range(gmatrix.shape[0]) if a % 3]
        sub = gmatrix[np.ix_(keep, keep)]
        for row in range(sub.shape[0]):
            gptr[f, row] = len(gval)
            for col in np.flatnonzero(sub[row]):
                gcol.append(int(col)), gval.append(float(sub[row, col]))
        gptr[f, sub.shape[0]] = len(gval)
        grows.append(sub.shape[0])
    theta = 2.0 * np.pi * np.arange(grid) / grid
    angle = solve_kinematics(linkage.mechanism, theta).angle
    values = np.zeros((grid, SCALARS))
    for link in range(3):
        values[:, 2 * link], values[:, 2 * link + 1] = np.cos(angle[link]), np.sin(angle[link])
    kappa = output_coefficients(linkage.mechanism, theta)
    if 0 not in linkage.links:
        kappa[:, :, 0] = 0.0
    values[:, 6:] = kappa.reshape(grid, 16)
    table = periodic_cell_coefficients(values)
    return {'vsel': np.ascontiguousarray(basis[used]), 'rows': np.arange(len(used)),
            'kind': kind, 'i0': i0, 'i1': i1, 'slot_link': slot_link, 'gptr': gptr.ravel(),
            'gcol': gcol, 'gval': gval, 'form_first': form_first, 'grows': grows, 'table': table,
            'grid': grid, 'slots': len(kind), 'used': len(used)}


def _int(values):
    return np.ascontiguousarray(values, dtype=np.int32)


def _call(lib, data, qs, thetas, repeat):
    def ptr(a, kind):
        return a.ctypes.data_as(ctypes.POINTER(kind))
    dbl, i32 = ctypes.c_double, ctypes.c_int
    arrays = {k: _int(data[k]) for k in ('rows', 'kind', 'i0', 'i1', 'slot_link', 'grows',
                                         'gptr', 'gcol', 'form_first')}
    gval = np.ascontiguousarray(data['gval'], dtype=float)
    table = np.ascontiguousarray(data['table'])
    qs, thetas = np.ascontiguousarray(qs), np.ascontiguousarray(thetas)
    out = np.zeros((len(thetas), 4))
    y, z = np.zeros(data['used'] + 1), np.zeros(data['slots'] + 1)
    lib.run.restype = dbl
    ns = lib.run(i32(len(thetas)), i32(repeat), i32(qs.shape[1]), i32(data['used']),
                 ptr(data['vsel'], dbl), ptr(arrays['rows'], i32), i32(data['slots']),
                 ptr(arrays['kind'], i32), ptr(arrays['i0'], i32), ptr(arrays['i1'], i32),
                 ptr(arrays['slot_link'], i32), i32(4), ptr(arrays['grows'], i32),
                 ptr(arrays['gptr'], i32),
                 ptr(arrays['gcol'], i32), ptr(gval, dbl), ptr(arrays['form_first'], i32),
                 i32(data['grid']), ptr(table, dbl), ptr(qs, dbl), ptr(thetas, dbl),
                 ptr(y, dbl), ptr(z, dbl), ptr(out, dbl))
    return ns, out


def time_factored(mechanism, bearings, rigid_crank, size, samples=20000, repeat=20):
    """
    Time the compiled factored step: nanoseconds per sample (checked against numpy).

    Parameters
    ----------
    mechanism : Mechanism
        The linkage.
    bearings : str
        'rigid' or 'flexible'.
    rigid_crank : bool
        Treat the crank as rigid.
    size : int
        Reduced size r (a random orthonormal basis of that size: the cost does not depend on
        the values).
    samples : int
        Samples per timed call.
    repeat : int
        Passes over the samples (the time per sample is their mean).

    Returns
    -------
    float

    """
    options = ModelOptions.linear(bearings=bearings, rigid_crank=rigid_crank, grid_size=8)
    linkage = FlexibleLinkage(fe_mechanism(mechanism, options),
                              options)
    rng = np.random.default_rng(1)
    basis = np.linalg.qr(rng.standard_normal((linkage.size, size)))[0]
    data = kernel_data(linkage, basis)
    with tempfile.TemporaryDirectory() as tmp:
        lib = _compile(tmp)
        grid_theta = 2.0 * np.pi * np.arange(data['grid']) / data['grid']
        q = rng.standard_normal((grid_theta.size, size)) * 1e-3
        _, out = _call(lib, data, q, grid_theta, 1)
        expected = factored_second_order(factored_forms(linkage, basis), mechanism,
                                         grid_theta, q)
        if not np.allclose(out, expected, rtol=1e-9, atol=1e-12 * np.abs(expected).max()):
            raise RuntimeError('the compiled kernel disagrees with factored_second_order')
        qs = rng.standard_normal((samples, size)) * 1e-3
        thetas = rng.uniform(0.0, 2.0 * np.pi, samples)
        ns, _ = _call(lib, data, qs, thetas, repeat)
    return ns


def _update_round(estimator, speed, samples, start):
    """Median ns of ``samples`` streaming updates at 1 kHz, constant speed, after ``start``."""
    stamps = start + 1 + np.arange(samples)
    signal = ((stamps * 1_000_000).tolist(), (speed * stamps * 1e-3).tolist(), [speed] * samples)
    times_us, _ = update_round(estimator, signal, settle=0)
    return float(np.median(times_us)) * 1e3


def _rows_round(estimator, speed, samples):
    """Ns (CPU) per row of the batched compiled step (the offline replay's path), one call."""
    angles = np.mod(speed * 1e-3 * (np.arange(samples) + 1.0), 2.0 * math.pi)
    rows = np.column_stack([np.full(samples, 1e-3), np.ones(samples), angles,
                            np.full(samples, speed), np.zeros(samples),
                            np.full(samples, speed * 1e-3)])
    records = np.empty((samples, estimator.last_record.size))
    # CPU time of the process: a batch of milliseconds is preempted on a loaded machine.
    before = time.process_time_ns()
    estimator.step_rows(rows, np.empty(0), records)
    return (time.process_time_ns() - before) / samples


def streaming_overhead(mechanism, options, rpm=391.0, rounds=9, samples=3000):
    """
    Time the second order in the compiled step: order 1 against order 2, alternating rounds.

    Each round runs ``samples`` in-process updates (StreamingEstimator.update, the node's
    call) on an order-1 and then an order-2 model of the same ``options`` (warm-started at
    ``rpm``), and one batched step of as many rows (step_rows, the replay's call).

    Returns
    -------
    dict
        'update_ns' and 'rows_ns': median over the rounds per order, and their difference
        'second_order_ns' (median of the per-round differences); 'size' r.

    """
    models = {order: model_for_mechanism(mechanism, dataclasses.replace(options, order=order))
              for order in (1, 2)}
    speed = rpm * math.pi / 30.0
    estimators = {order: StreamingEstimator(model) for order, model in models.items()}
    for estimator in estimators.values():
        estimator.update(0, 0.0, speed)
    update = {1: [], 2: []}
    rows = {1: [], 2: []}
    for k in range(rounds):
        for order, estimator in estimators.items():
            update[order].append(_update_round(estimator, speed, samples, k * samples))
            rows[order].append(_rows_round(estimator, speed, samples))
    out = {'size': models[2].size, 'compiled': estimators[2].compiled}
    for name, values in (('update_ns', update), ('rows_ns', rows)):
        out[name] = {order: float(np.median(v)) for order, v in values.items()}
        out[name]['second_order_ns'] = float(np.median(np.subtract(values[2], values[1])))
    return out


def main(argv=None):
    """Print :func:`streaming_overhead` for the node's default and the rigid-crank models."""
    parser = argparse.ArgumentParser(prog='python benchmarks/second_order_bench.py',
                                     description=__doc__.strip().splitlines()[0])
    parser.add_argument('--mechanism', default='cho1992')
    parser.add_argument('--rounds', type=int, default=9)
    parser.add_argument('--samples', type=int, default=3000)
    parser.add_argument('--json', action='store_true')
    args = parser.parse_args(argv)
    mechanism = load_mechanism(args.mechanism)
    cases = [('node default (flexible crank, 4 el.)',
              ModelOptions.linear(rigid_crank=False, elements_per_link=4)),
             ('rigid crank, flexible bearings', ModelOptions.linear()),
             ('rigid crank, rigid bearings', ModelOptions.linear(bearings='rigid'))]
    results = []
    for label, options in cases:
        entry = streaming_overhead(mechanism, options, rounds=args.rounds, samples=args.samples)
        results.append({'case': label, **entry})
        if not args.json:
            u, r = entry['update_ns'], entry['rows_ns']
            size, u_second, r_second = entry['size'], u['second_order_ns'], r['second_order_ns']
            print(f'{label:38s} r={size:2d}  update {u[1] / 1e3:6.2f} / {u[2] / 1e3:6.2f} us '
                  f'(order 1 / 2), second order {u_second / 1e3:+.2f} us; batched step '
                  f'{r[1] / 1e3:6.2f} / {r[2] / 1e3:6.2f} us, second order '
                  f'{r_second / 1e3:+.2f} us')
    if args.json:
        print(json.dumps(results, indent=1))
    return 0


__all__ = ['KERNEL', 'kernel_data', 'time_factored', 'streaming_overhead', 'main']


if __name__ == '__main__':
    raise SystemExit(main())
