"""The linear delay system of Chen (1995) and its checks.

Retarded (``B`` empty) and neutral systems with commensurate delays ``k h``::

    x'(t) - sum_k B_k x'(t - k h) = A0 x(t) + sum_k A_k x(t - k h),   k = 1..q,

with characteristic matrix ``T(s, h) = s N(z) - M(z)``, ``z = exp(-s h)``,
``M(z) = A0 + sum_k A_k z^k`` and ``N(z) = I - sum_k B_k z^k``. Time in seconds,
``h`` in seconds, frequencies in rad/s.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .. import validate as v
from ..errors import InputError
from ..io import did_you_mean

__all__ = ["DelaySystem", "read_delay_system"]

#: A neutral difference operator whose companion spectral radius is within this of 1
#: is refused: its stability is decided by rounding, not by the data.
MARGINAL_RADIUS_TOL = 1e-9

#: Eigenvalues of the delay-free system with real part above ``-this * scale`` count as
#: not in the open left half-plane (``scale`` = norm of the system matrix).
HURWITZ_TOL = 1e-12


def _as_matrix(value: Any, name: str) -> np.ndarray:
    v.real_numbers(name, value, "a real matrix of numbers")
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a real matrix of numbers; got {value!r:.80}") from None
    if arr.ndim == 0 or arr.shape == (1,):
        arr = arr.reshape(1, 1)
    if arr.ndim != 2 or arr.shape[0] != arr.shape[1]:
        raise InputError(f"{name} must be a square matrix; got shape {arr.shape}")
    bad = np.argwhere(~np.isfinite(arr))
    if bad.size:
        i, j = bad[0]
        raise InputError(f"{name}[{i}, {j}] is {arr[i, j]}; every entry must be finite")
    return arr


def _as_matrix_list(value: Any, name: str, n: int) -> list[np.ndarray]:
    if value is None:
        return []
    if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
        if n == 1:
            value = [value]
        else:
            raise InputError(f"{name} must be a list of {n}x{n} matrices; got {value!r:.80}")
    v.real_numbers(name, value, "a real matrix of numbers")
    try:
        whole = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        whole = None
    if whole is not None and n > 1 and whole.shape == (n, n):
        raise InputError(f"{name} must be a list of {n}x{n} matrices [A1, ..., Aq]; got one "
                         f"{n}x{n} matrix: wrap it in a list")
    scalars = whole is not None and n == 1 and whole.ndim <= 1
    items = list(whole.reshape(-1, 1, 1)) if scalars else list(value)
    out = []
    for k, item in enumerate(items, start=1):
        mat = _as_matrix(item, f"{name}[{k - 1}] (delay {k} h)")
        if mat.shape != (n, n):
            raise InputError(f"{name}[{k - 1}] (delay {k} h) has shape {mat.shape}; it must "
                             f"match A0, which is {n}x{n}")
        out.append(mat)
    return out


def _companion_radius(b_list: list[np.ndarray]) -> float:
    """Spectral radius of the block companion of ``mu^q I - sum_k B_k mu^(q-k)``."""
    q = len(b_list)
    if q == 0 or not any(np.any(b) for b in b_list):
        return 0.0
    n = b_list[0].shape[0]
    comp = np.zeros((q * n, q * n))
    comp[:n, :] = np.hstack(b_list)
    comp[n:, :-n] = np.eye((q - 1) * n)
    return float(np.max(np.abs(np.linalg.eigvals(comp))))


@dataclass(frozen=True, eq=False)
class DelaySystem:
    """A validated linear system with commensurate delays ``h, 2h, ..., q h``.

    Parameters
    ----------
    A0 : array_like, shape (n, n)
        Matrix of the undelayed state (a scalar is a 1x1 matrix).
    A : sequence of array_like, shape (n, n) each
        ``[A1, ..., Aq]``: ``A_k`` multiplies ``x(t - k h)``.
    B : sequence of array_like, shape (n, n) each, optional
        Neutral terms ``[B1, ..., Bq]``: ``B_k`` multiplies ``x'(t - k h)`` on the
        left-hand side. ``None`` (default): retarded system. A shorter list of ``A`` or
        ``B`` is padded with zero matrices; trailing zero terms are dropped.

    Attributes
    ----------
    A0 : numpy.ndarray
    A : tuple of numpy.ndarray
    B : tuple of numpy.ndarray
        Same length as ``A`` (zeros for a retarded system).
    n, q : int
        State dimension and number of delay terms.
    neutral : bool
        Whether any ``B_k`` is nonzero.
    """

    A0: np.ndarray
    A: tuple
    B: tuple

    def __init__(self, A0: Any, A: Any, B: Any = None) -> None:
        a0 = _as_matrix(A0, "A0")
        n = a0.shape[0]
        a_list = _as_matrix_list(A, "A", n)
        b_list = _as_matrix_list(B, "B", n)
        q = max(len(a_list), len(b_list))
        zero = np.zeros((n, n))
        a_list += [zero] * (q - len(a_list))
        b_list += [zero] * (q - len(b_list))
        while q and not np.any(a_list[-1]) and not np.any(b_list[-1]):
            q -= 1
            a_list.pop()
            b_list.pop()
        object.__setattr__(self, "A0", a0)
        object.__setattr__(self, "A", tuple(a_list))
        object.__setattr__(self, "B", tuple(b_list))

    @property
    def n(self) -> int:
        """State dimension ``n``."""
        return int(self.A0.shape[0])

    @property
    def q(self) -> int:
        """Number of delay terms ``q`` (the largest delay is ``q h``)."""
        return len(self.A)

    @property
    def neutral(self) -> bool:
        """Whether the system is of neutral type (some ``B_k`` nonzero)."""
        return any(np.any(b) for b in self.B)

    @property
    def scale(self) -> float:
        """``||A0|| + sum ||A_k||`` (2-norms, 1/s): the frequency scale of the system."""
        s = np.linalg.norm(self.A0, 2) + sum(np.linalg.norm(a, 2) for a in self.A)
        return float(s) if s > 0 else 1.0

    def __repr__(self) -> str:
        kind = "neutral" if self.neutral else "retarded"
        return f"DelaySystem(n={self.n}, q={self.q}, {kind})"

    def difference_radius(self) -> float:
        """Spectral radius of the companion matrix of ``B1, ..., Bq``.

        The difference operator ``x(t) - sum_k B_k x(t - k h)`` is stable for every
        ``h > 0`` when it is below 1; above 1 the neutral system is unstable for
        every ``h > 0``.

        Returns
        -------
        float
            0 for a retarded system.
        """
        return _companion_radius(list(self.B))

    def check_difference_operator(self) -> float:
        """Refuse a neutral system whose difference operator is marginal.

        Returns
        -------
        float
            :meth:`difference_radius`, when it is not within
            :data:`MARGINAL_RADIUS_TOL` of 1.

        Raises
        ------
        InputError
            When the radius is 1 to within :data:`MARGINAL_RADIUS_TOL`.
        """
        rho = self.difference_radius()
        if abs(rho - 1.0) <= MARGINAL_RADIUS_TOL:
            raise InputError(
                f"B: the neutral difference operator is not strongly stable: spectral radius "
                f"of the companion of B1..Bq is {rho:.12g}, which is 1 to within "
                f"{MARGINAL_RADIUS_TOL:g}; stability then depends on rounding, so no delay "
                f"margin is defined; make it below 1")
        return rho

    def delay_free_matrix(self) -> np.ndarray:
        """The matrix of the system at ``h = 0``: ``(I - sum B_k)^-1 (A0 + sum A_k)``.

        Returns
        -------
        numpy.ndarray, shape (n, n)
            The state matrix of ``x' = X x`` at ``h = 0``.
        """
        m = self.A0 + sum(self.A, np.zeros_like(self.A0))
        nmat = np.eye(self.n) - sum(self.B, np.zeros_like(self.A0))
        return np.linalg.solve(nmat, m)

    def unstable_at_zero(self) -> int:
        """Number of eigenvalues of the delay-free system not in the open left half-plane.

        Returns
        -------
        int
            0 when the system is stable at ``h = 0``.
        """
        mat = self.delay_free_matrix()
        eig = np.linalg.eigvals(mat)
        tol = HURWITZ_TOL * max(1.0, float(np.linalg.norm(mat, 2)))
        return int(np.sum(eig.real >= -tol))

    def M(self, z: complex) -> np.ndarray:
        """``M(z) = A0 + sum_k A_k z^k``.

        Parameters
        ----------
        z : complex
            ``exp(-s h)``.

        Returns
        -------
        numpy.ndarray, shape (n, n), complex
            The matrix.
        """
        out = self.A0.astype(complex)
        for k, a in enumerate(self.A, start=1):
            out = out + a * z**k
        return out

    def N(self, z: complex) -> np.ndarray:
        """``N(z) = I - sum_k B_k z^k``.

        Parameters
        ----------
        z : complex
            ``exp(-s h)``.

        Returns
        -------
        numpy.ndarray, shape (n, n), complex
            The matrix.
        """
        out = np.eye(self.n, dtype=complex)
        for k, b in enumerate(self.B, start=1):
            out = out - b * z**k
        return out

    def characteristic_matrix(self, s: complex, h: float) -> np.ndarray:
        """``T(s, h) = s N(exp(-s h)) - M(exp(-s h))``.

        Parameters
        ----------
        s : complex
            Laplace variable (1/s).
        h : float
            Delay (s).

        Returns
        -------
        numpy.ndarray, shape (n, n), complex
            The characteristic matrix (1/s).
        """
        z = np.exp(-s * h)
        return s * self.N(z) - self.M(z)


def read_delay_system(path: str | Path) -> DelaySystem:
    """Read the ``[delay_system]`` table of a TOML file.

    The table has ``A0 = [[...], ...]``, ``A = [[[...]], ...]`` (``A1 .. Aq``) and
    optionally ``B = [[[...]], ...]`` (neutral terms), as :class:`DelaySystem` takes them.

    Parameters
    ----------
    path : str or pathlib.Path
        The TOML file.

    Returns
    -------
    DelaySystem
        The validated system.

    Raises
    ------
    InputError
        When the file is a directory or not TOML, the table or a key is missing or
        unknown, or a matrix is invalid (the message names the file and the key).
    FileNotFoundError
        If the file does not exist.
    """
    from ..io import load_toml

    path = Path(path)
    doc = load_toml(path)
    table = doc.get("delay_system")
    if not isinstance(table, dict):
        raise InputError(f"{path}: no [delay_system] table; add one with A0 = [[...]] and "
                         f"A = [[[...]], ...]")
    others = sorted(set(doc) - {"delay_system"})
    if others:
        raise InputError(f"{path}: unknown top-level key(s) or table(s) {', '.join(others)}; "
                         "a delay system file holds only [delay_system]")
    unknown = sorted(set(table) - {"A0", "A", "B"})
    if unknown:
        raise InputError(f"{path}: [delay_system] has unknown key(s) {', '.join(unknown)}"
                         f"{did_you_mean(unknown, ['A0', 'A', 'B'])}; allowed: A0, A, B")
    for key in ("A0", "A"):
        if key not in table:
            raise InputError(f"{path}: [delay_system] needs {key}")
    try:
        return DelaySystem(table["A0"], table["A"], table.get("B"))
    except InputError as exc:
        raise InputError(f"{path}: [delay_system] {exc}") from None
