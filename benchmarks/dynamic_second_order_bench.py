"""
Time, compiled, the per-sample work the dynamic second-order pass adds to the streaming step.

A small C kernel (compiled here with ``cc -O3``, as ``benchmarks/second_order_bench.py`` does) runs
per sample what a compiled step with the pass (core/estimation/second_order_dynamic_step.py) adds
to the linear step: the reduced static responses K_r^-1 f_r at the two Radau stages (their axial
forces are the reference of the elastic axial force), the reduced second-order load f2 at the two
stages (:class:`core.reduction.second_order_dynamic_tables.DynamicLoad`: per link the rotated
gather B = B0 + c Bc + s Bs, u = B q, the elements' eigenstrain and geometric-stiffness loads,
B^T f), the second right-hand side and its forward and back substitution with the linear step's LU
factors (2 r), K_r^-1 f2_eigenstrain at the sample and the output operator on q2. Not included: the
spline of the angle scalars (a few hundred multiply-adds) and the larger basis the pass needs
(timed in ``cost`` of ``docs/studies/dynamic_second_order_study.py``). The stage load is checked
against the numpy load before it is timed. Needs a C compiler; nothing here is used by the package
at run time.
"""

import ctypes
import pathlib
import shutil
import subprocess
import tempfile

import numpy as np


KERNEL = r"""
#include <math.h>
#include <string.h>
#include <time.h>
static void stage_load(int r, int nl, int d, const double *pieces, const int *links,
                       const double *vals, const double *unit, const double *trig,
                       const double *q, const double *qs, double *gather, double *local,
                       double *slocal, double *loads, double *out)
{
    memset(out, 0, sizeof(double) * 2 * r);
    for (int n = 0; n < nl; ++n) {
        int row = links[3 * n], e = links[3 * n + 1], rows = 3 * (e + 1);
        double c = trig[2 * n], s = trig[2 * n + 1], l = vals[2 * n], ea = vals[2 * n + 1];
        const double *p0 = pieces + row * r, *pc = p0 + d * r, *ps = pc + d * r;
        const double *g = unit + 36 * n;
        for (int a = 0; a < rows * r; ++a) gather[a] = p0[a] + c * pc[a] + s * ps[a];
        for (int a = 0; a < rows; ++a) {
            double x = 0.0, y = 0.0;
            for (int k = 0; k < r; ++k) { x += gather[a * r + k] * q[k];
                                          y += gather[a * r + k] * qs[k]; }
            local[a] = x; slocal[a] = y;
        }
        memset(loads, 0, sizeof(double) * 2 * rows);
        for (int el = 0; el < e; ++el) {
            const double *u = local + 3 * el;
            double gu[6], sh = 0.0;
            for (int i = 0; i < 6; ++i) {
                double acc = 0.0;
                for (int j = 0; j < 6; ++j) acc += g[6 * i + j] * u[j];
                gu[i] = acc; sh += acc * u[i];
            }
            double pull = 0.5 * ea * sh / l;
            double ne = ea / l * ((u[3] - u[0]) - (slocal[3 * el + 3] - slocal[3 * el]));
            double *f0 = loads + 3 * el, *f1 = loads + rows + 3 * el;
            for (int i = 0; i < 6; ++i) f0[i] -= ne * gu[i];
            f0[0] += pull; f0[3] -= pull; f1[0] += pull; f1[3] -= pull;
        }
        for (int a = 0; a < rows; ++a) {
            double x = loads[a], y = loads[rows + a];
            for (int k = 0; k < r; ++k) { out[k] += x * gather[a * r + k];
                                          out[r + k] += y * gather[a * r + k]; }
        }
    }
}
static void solve(int n, double *a, double *b)   /* Gaussian elimination, partial pivoting */
{
    for (int k = 0; k < n; ++k) {
        int p = k;
        for (int i = k + 1; i < n; ++i)
            if (fabs(a[i * n + k]) > fabs(a[p * n + k])) p = i;
        if (p != k) { for (int j = 0; j < n; ++j) { double t = a[k * n + j];
                      a[k * n + j] = a[p * n + j]; a[p * n + j] = t; }
                      double t = b[k]; b[k] = b[p]; b[p] = t; }
        for (int i = k + 1; i < n; ++i) {
            double f = a[i * n + k] / a[k * n + k];
            for (int j = k; j < n; ++j) a[i * n + j] -= f * a[k * n + j];
            b[i] -= f * b[k];
        }
    }
    for (int i = n - 1; i >= 0; --i) {
        double acc = b[i];
        for (int j = i + 1; j < n; ++j) acc -= a[i * n + j] * b[j];
        b[i] = acc / a[i * n + i];
    }
}
static void substitute(int n, const double *lu, const int *piv, double *b)
{
    for (int i = 0; i < n; ++i) { int p = piv[i]; double t = b[i]; b[i] = b[p]; b[p] = t; }
    for (int i = 0; i < n; ++i) for (int j = 0; j < i; ++j) b[i] -= lu[i * n + j] * b[j];
    for (int i = n - 1; i >= 0; --i) {
        for (int j = i + 1; j < n; ++j) b[i] -= lu[i * n + j] * b[j];
        b[i] /= lu[i * n + i];
    }
}
void one_load(int r, int nl, int d, const double *pieces, const int *links, const double *vals,
              const double *unit, const double *trig, const double *q, const double *qs,
              double *work, double *out)
{
    stage_load(r, nl, d, pieces, links, vals, unit, trig, q, qs, work, work + 3 * d * r,
               work + 3 * d * r + d, work + 3 * d * r + 2 * d, out);
}
double run(int samples, int r, int nl, int d, const double *pieces, const int *links,
           const double *vals, const double *unit, const double *trig, const double *qs_in,
           const double *kmat, const double *lu, const int *piv, const double *op,
           const double *outop, double *work, double *z2, double *sink, int solves)
{
    struct timespec t0, t1;
    double *kw = work + 3 * d * r + 4 * d, *stat = kw + r * r, *f2 = stat + 2 * r;
    double *rhs = f2 + 4 * r;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t0);
    for (int n = 0; n < samples; ++n) {
        const double *q = qs_in + n * r;
        for (int st = 0; st < 2; ++st) {        /* static responses at the stages */
            for (int k = 0; k < r; ++k) stat[st * r + k] = q[k] * 1e-3 + kmat[k];
            if (solves) {
                memcpy(kw, kmat + st * r * r, sizeof(double) * r * r);
                solve(r, kw, stat + st * r);
            }
            one_load(r, nl, d, pieces, links, vals, unit, trig + n * 2 * nl, q, stat + st * r,
                     work, f2 + 2 * st * r);
        }
        for (int i = 0; i < 2 * r; ++i) {       /* z2 operator + the stage loads */
            double acc = (i < r) ? f2[i] : f2[2 * r + i - r];
            for (int j = 0; j < 2 * r; ++j) acc += op[i * 2 * r + j] * z2[j];
            rhs[i] = acc;
        }
        substitute(2 * r, lu, piv, rhs);
        for (int i = 0; i < 2 * r; ++i) z2[i] += 1e-3 * rhs[i];
        memcpy(stat, f2 + 3 * r, sizeof(double) * r);
        if (solves) {                                        /* K_r^-1 f2_eig at the sample */
            memcpy(kw, kmat + r * r, sizeof(double) * r * r);
            solve(r, kw, stat);
        }
        for (int o = 0; o < 4; ++o) {
            double acc = 0.0;
            for (int k = 0; k < r; ++k) acc += outop[o * r + k] * (z2[k] - stat[k]);
            sink[o] += acc;
        }
    }
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t1);
    return ((t1.tv_sec - t0.tv_sec) * 1e9 + (t1.tv_nsec - t0.tv_nsec)) / (double)samples;
}
"""


def _compile(directory):
    compiler = shutil.which('cc') or shutil.which('gcc')
    if compiler is None:
        raise RuntimeError('no C compiler (cc) on PATH')
    source = pathlib.Path(directory) / 'dynamic_pass_kernel.c'
    library = pathlib.Path(directory) / 'dynamic_pass_kernel.so'
    source.write_text(KERNEL)
    subprocess.run([compiler, '-O3', '-shared', '-fPIC', str(source), '-o', str(library), '-lm'],
                   check=True, capture_output=True)
    return ctypes.CDLL(str(library))


def _ptr(array, kind=ctypes.c_double):
    return array.ctypes.data_as(ctypes.POINTER(kind))


def time_pass(load, samples=20000, seed=0, solves=True):
    """
    Return (ns per sample, largest relative difference of the C stage load from numpy's).

    ``solves`` False leaves out the three r x r solves (K_r^-1 f_r at the stages and
    K_r^-1 f2_eigenstrain): the cost if their results came from tables.

    ``load`` a :class:`DynamicLoad`; the states, the K_r and the stage-system LU factors are
    random (well conditioned): the work per sample does not depend on their values.
    """
    rng = np.random.default_rng(seed)
    r, d = load.pieces.shape[2], load.pieces.shape[1]
    links = np.ascontiguousarray(load.arrays['dynamic_links'], dtype=np.int32)
    nl = links.shape[0]
    vals = np.ascontiguousarray(load.arrays['dynamic_link_values'])
    unit = np.ascontiguousarray(load.arrays['dynamic_unit'])
    pieces = np.ascontiguousarray(load.pieces)
    angles = rng.uniform(0.0, 2.0 * np.pi, samples)
    scalars = np.array([load.spline_scalars(a) for a in angles[:64]])
    trig = np.ascontiguousarray(np.resize(scalars[:, :2 * nl], (samples, 2 * nl)))
    qs = np.ascontiguousarray(rng.standard_normal((samples, r)) * 1e-3)
    work = np.zeros(3 * d * r + 4 * d + r * r + 8 * r + 2 * r)
    with tempfile.TemporaryDirectory() as directory:
        lib = _compile(directory)
        # the stage load against numpy, with a static reference state
        out = np.zeros(2 * r)
        q, reference = qs[0], qs[1]
        lib.one_load(r, nl, d, _ptr(pieces), _ptr(links, ctypes.c_int), _ptr(vals), _ptr(unit),
                     _ptr(trig[0]), _ptr(q), _ptr(reference), _ptr(work), _ptr(out))
        scalar = np.zeros(scalars.shape[1])
        scalar[:2 * nl] = trig[0]
        total, eigen = load.load_at_scalars(q, scalar, 0.0, 0.0, reference)
        scale = np.abs(total).max()
        error = max(np.abs(out[:r] - total).max(), np.abs(out[r:] - eigen).max()) / scale
        kmat = np.ascontiguousarray(np.eye(r) * 10.0 + rng.standard_normal((2, r, r)))
        lu = np.ascontiguousarray(np.eye(2 * r) * 5.0 + np.tril(rng.standard_normal((2 * r,) * 2)))
        piv = np.arange(2 * r, dtype=np.int32)
        op = np.ascontiguousarray(rng.standard_normal((2 * r, 2 * r)) * 1e-2)
        outop = np.ascontiguousarray(rng.standard_normal((4, r)))
        z2, sink = np.zeros(2 * r), np.zeros(4)
        lib.run.restype = ctypes.c_double
        ns = lib.run(samples, r, nl, d, _ptr(pieces), _ptr(links, ctypes.c_int), _ptr(vals),
                     _ptr(unit), _ptr(trig), _ptr(qs), _ptr(kmat), _ptr(lu),
                     _ptr(piv, ctypes.c_int), _ptr(op), _ptr(outop), _ptr(work), _ptr(z2),
                     _ptr(sink), int(bool(solves)))
    return float(ns), float(error)


__all__ = ['KERNEL', 'time_pass']
