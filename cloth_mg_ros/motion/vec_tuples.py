"""3-vectors (tuples of 3) and 3x3 matrices (tuples of 9, row-major) for numba kernels: nogil
scalar code, no array allocated per operation (`joint_frames` solves a body with them).
Division by a zero length gives NaN or inf (error_model='numpy'), never an exception."""

from __future__ import annotations

import math

from numba import njit

__all__ = ['add', 'cross', 'dot', 'get', 'mid', 'mm', 'mmt', 'mv', 'norm', 'put', 'scale', 'sub',
           'unit']


@njit(cache=True, nogil=True, error_model='numpy')
def get(P, i):
    return (P[i, 0], P[i, 1], P[i, 2])


@njit(cache=True, nogil=True, error_model='numpy')
def put(P, i, v):
    P[i, 0], P[i, 1], P[i, 2] = v[0], v[1], v[2]


@njit(cache=True, nogil=True, error_model='numpy')
def add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@njit(cache=True, nogil=True, error_model='numpy')
def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@njit(cache=True, nogil=True, error_model='numpy')
def scale(s, a):
    return (s * a[0], s * a[1], s * a[2])


@njit(cache=True, nogil=True, error_model='numpy')
def mid(a, b):
    return (0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]), 0.5 * (a[2] + b[2]))


@njit(cache=True, nogil=True, error_model='numpy')
def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, nogil=True, error_model='numpy')
def norm(a):
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


@njit(cache=True, nogil=True, error_model='numpy')
def unit(a):
    n = norm(a)
    return (a[0] / n, a[1] / n, a[2] / n)


@njit(cache=True, nogil=True, error_model='numpy')
def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(cache=True, nogil=True, error_model='numpy')
def mv(M, v):
    return (M[0] * v[0] + M[1] * v[1] + M[2] * v[2], M[3] * v[0] + M[4] * v[1] + M[5] * v[2],
            M[6] * v[0] + M[7] * v[1] + M[8] * v[2])


@njit(cache=True, nogil=True, error_model='numpy')
def mm(A, B):
    """A @ B."""
    return (A[0] * B[0] + A[1] * B[3] + A[2] * B[6], A[0] * B[1] + A[1] * B[4] + A[2] * B[7],
            A[0] * B[2] + A[1] * B[5] + A[2] * B[8], A[3] * B[0] + A[4] * B[3] + A[5] * B[6],
            A[3] * B[1] + A[4] * B[4] + A[5] * B[7], A[3] * B[2] + A[4] * B[5] + A[5] * B[8],
            A[6] * B[0] + A[7] * B[3] + A[8] * B[6], A[6] * B[1] + A[7] * B[4] + A[8] * B[7],
            A[6] * B[2] + A[7] * B[5] + A[8] * B[8])


@njit(cache=True, nogil=True, error_model='numpy')
def mmt(A, B):
    """A @ B.T."""
    return (A[0] * B[0] + A[1] * B[1] + A[2] * B[2], A[0] * B[3] + A[1] * B[4] + A[2] * B[5],
            A[0] * B[6] + A[1] * B[7] + A[2] * B[8], A[3] * B[0] + A[4] * B[1] + A[5] * B[2],
            A[3] * B[3] + A[4] * B[4] + A[5] * B[5], A[3] * B[6] + A[4] * B[7] + A[5] * B[8],
            A[6] * B[0] + A[7] * B[1] + A[8] * B[2], A[6] * B[3] + A[7] * B[4] + A[8] * B[5],
            A[6] * B[6] + A[7] * B[7] + A[8] * B[8])
