"""Exact zero-order-hold stepping of the particle blocks in modal (eigen) coordinates.

Each block ``dy/dt = A y + b I`` is diagonalised once, ``A = V diag(lam) V^-1``; in the modal
coordinates ``z = V^-1 y`` a step of length ``h`` under a constant current ``I`` is exact:

    z <- exp(lam h) z + phi(lam, h) (V^-1 b) I,     phi(lam, h) = (exp(lam h) - 1) / lam

(``phi = h`` for the conserved mode, ``lam = 0``). The surface value is ``s = (m V) . z``.
Parameter sets that scale ``A`` by a factor ``f_A`` and ``b`` by ``f_b`` (see
:mod:`battery_predictor.simulation.engine.model`) keep the eigenvectors: their eigenvalues are
``f_A lam`` and their input vector ``f_b V^-1 b``, so one decomposition serves every set.

The recurrence over the steps runs in a compiled kernel when Numba is installed, else in NumPy
(a linear filter per mode for a single set on uniform steps, a loop over steps vectorised over
sets and modes otherwise).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from types import ModuleType

import numpy as np
import numpy.typing as npt

from battery_predictor.errors import SimulationError
from battery_predictor.simulation.engine.model import LinearSpm, ParticleBlock

#: Eigenvalues smaller than this fraction of the largest are the conserved mode (exactly zero).
_ZERO_EIGENVALUE_FRACTION = 1e-10
#: Largest accepted reconstruction error of the eigendecomposition (relative to |A|).
_DECOMPOSITION_RTOL = 1e-9


@dataclass(frozen=True)
class ModalSystem:
    """Both particle blocks in modal coordinates (negative modes first).

    Attributes
    ----------
    eigenvalues_per_s : numpy.ndarray
        ``lam`` of every mode (1/s, <= 0), shape (n_modes,).
    input_per_a_s : numpy.ndarray
        ``V^-1 b`` (1/(A s)), shape (n_modes,).
    surface_weights : numpy.ndarray
        ``m V`` per electrode, shape (2, n_modes), zero outside the electrode's modes.
    to_modal : tuple of numpy.ndarray
        ``V^-1`` of each block.
    from_modal : tuple of numpy.ndarray
        ``V`` of each block.
    n_negative : int
        Number of negative-electrode modes.
    """

    eigenvalues_per_s: np.ndarray
    input_per_a_s: np.ndarray
    surface_weights: np.ndarray
    to_modal: tuple[np.ndarray, np.ndarray]
    from_modal: tuple[np.ndarray, np.ndarray]
    n_negative: int

    @property
    def n_modes(self) -> int:
        return int(self.eigenvalues_per_s.size)

    def electrode_factors(self, negative: npt.ArrayLike, positive: npt.ArrayLike) -> np.ndarray:
        """Per-mode array from per-electrode values of shape (n_sets,): shape (n_sets, n_modes)."""
        neg = np.asarray(negative, dtype=float).reshape(-1, 1)
        pos = np.asarray(positive, dtype=float).reshape(-1, 1)
        n_pos = self.n_modes - self.n_negative
        return np.hstack([np.repeat(neg, self.n_negative, axis=1), np.repeat(pos, n_pos, axis=1)])

    def modal_state(self, y_negative: np.ndarray, y_positive: np.ndarray) -> np.ndarray:
        """Modal coordinates of PyBaMM block states (n,) or (n_sets, n): shape (n_sets, n_modes)."""
        zn = np.atleast_2d(y_negative) @ self.to_modal[0].T
        zp = np.atleast_2d(y_positive) @ self.to_modal[1].T
        return np.hstack(np.broadcast_arrays(zn, zp))

    def block_states(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """PyBaMM block states (stoichiometry profiles) of modal states (n_sets, n_modes)."""
        z = np.atleast_2d(z)
        return z[:, : self.n_negative] @ self.from_modal[0].T, z[:, self.n_negative:] @ self.from_modal[1].T


def _decompose(block: ParticleBlock) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    a = block.a_matrix_per_s
    lam, vec = np.linalg.eig(a)
    if np.abs(lam.imag).max() > 0.0 or np.abs(vec.imag).max() > 0.0:
        raise SimulationError(f"the {block.electrode} particle matrix has complex eigenvalues")
    lam, vec = lam.real, vec.real
    order = np.argsort(-lam)
    lam, vec = lam[order], vec[:, order]
    scale = float(np.abs(lam).max())
    lam = np.where(np.abs(lam) < _ZERO_EIGENVALUE_FRACTION * scale, 0.0, lam)
    if np.any(lam > 0.0):
        raise SimulationError(f"the {block.electrode} particle matrix has a growing mode")
    inv = np.linalg.inv(vec)
    err = np.abs(vec @ np.diag(lam) @ inv - a).max()
    if err > _DECOMPOSITION_RTOL * np.abs(a).max():
        raise SimulationError(f"the {block.electrode} particle matrix is not diagonalisable to working accuracy")
    return lam, vec, inv


def modal_system(model: LinearSpm) -> ModalSystem:
    """Diagonalise both particle blocks of ``model``."""
    lams, inputs, invs, vecs, weights = [], [], [], [], []
    for block in model.blocks:
        lam, vec, inv = _decompose(block)
        vecs.append(vec)
        lams.append(lam)
        inputs.append(inv @ block.b_vector_per_a_s)
        invs.append(inv)
        weights.append(block.surface_row @ vec)
    n_neg = lams[0].size
    surface = np.zeros((2, n_neg + lams[1].size))
    surface[0, :n_neg] = weights[0]
    surface[1, n_neg:] = weights[1]
    return ModalSystem(eigenvalues_per_s=np.concatenate(lams), input_per_a_s=np.concatenate(inputs),
                       surface_weights=surface, to_modal=(invs[0], invs[1]),
                       from_modal=(vecs[0], vecs[1]), n_negative=n_neg)


def step_coefficients(lam: np.ndarray, duration_s: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``exp(lam h)`` and ``phi(lam, h)`` elementwise (broadcast), exact for ``lam = 0``."""
    x = lam * duration_s
    decay = np.exp(x)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = np.where(lam == 0.0, duration_s + 0.0 * lam, np.expm1(x) / np.where(lam == 0.0, 1.0, lam))
    return decay, phi


# --------------------------------------------------------------------------- recurrences
def _boundary_states_numpy(lam: np.ndarray, drive: np.ndarray, z0: np.ndarray, duration_s: np.ndarray,
                           current_a: np.ndarray, weights: np.ndarray,
                           stride: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """NumPy recurrence; see :func:`boundary_surfaces`."""
    n_sets, n_modes = z0.shape
    n_steps = duration_s.size
    surfaces = np.empty((n_sets, n_steps + 1, 2))
    checkpoints = np.empty((n_sets, n_steps // stride + 1, n_modes))
    uniform = n_steps > 0 and np.all(duration_s == duration_s[0])
    if uniform and n_sets == 1:
        from scipy.signal import lfilter

        decay, phi = step_coefficients(lam[0], duration_s[0])
        forcing = np.outer(current_a, phi * drive[0])  # (n_steps, n_modes)
        z = np.empty((n_steps + 1, n_modes))
        z[0] = z0[0]
        for j in range(n_modes):
            z[1:, j], _ = lfilter([1.0], [1.0, -decay[j]], forcing[:, j], zi=[decay[j] * z0[0, j]])
        surfaces[0] = z @ weights.T
        checkpoints[0] = z[::stride]
        return surfaces, checkpoints, z[-1:].copy()
    z = z0.copy()
    last_h = np.nan
    for k in range(n_steps):
        if k % stride == 0:
            checkpoints[:, k // stride] = z
        surfaces[:, k] = z @ weights.T
        h = duration_s[k]
        if h != last_h:
            decay, phi = step_coefficients(lam, h)
            phi_drive = phi * drive
            last_h = h
        z = decay * z + phi_drive * current_a[k]
    surfaces[:, n_steps] = z @ weights.T
    if n_steps % stride == 0:
        checkpoints[:, n_steps // stride] = z
    return surfaces, checkpoints, z


def _numba_kernel() -> Callable[..., None] | None:
    """The compiled recurrence, or None without Numba."""
    try:
        import numba
    except ImportError:
        return None
    return _compile(numba)


_KERNEL_CACHE: dict[str, Callable[..., None]] = {}


def _compile(numba: ModuleType) -> Callable[..., None]:
    if "kernel" in _KERNEL_CACHE:
        return _KERNEL_CACHE["kernel"]

    @numba.njit(cache=True, fastmath=False, nogil=True)
    def kernel(lam: np.ndarray, drive: np.ndarray, z0: np.ndarray, duration_s: np.ndarray, current_a: np.ndarray,
               weights: np.ndarray, stride: int, surfaces: np.ndarray, checkpoints: np.ndarray,
               z_end: np.ndarray) -> None:  # pragma: no cover - compiled
        n_sets, n_modes = z0.shape
        n_steps = duration_s.shape[0]
        decay = np.empty(n_modes)
        phid = np.empty(n_modes)
        z = np.empty(n_modes)
        for s in range(n_sets):
            for j in range(n_modes):
                z[j] = z0[s, j]
            last_h = -1.0
            for k in range(n_steps + 1):
                if k % stride == 0:
                    for j in range(n_modes):
                        checkpoints[s, k // stride, j] = z[j]
                sn = 0.0
                sp = 0.0
                for j in range(n_modes):
                    sn += weights[0, j] * z[j]
                    sp += weights[1, j] * z[j]
                surfaces[s, k, 0] = sn
                surfaces[s, k, 1] = sp
                if k == n_steps:
                    break
                h = duration_s[k]
                if h != last_h:
                    for j in range(n_modes):
                        x = lam[s, j] * h
                        decay[j] = np.exp(x)
                        if lam[s, j] == 0.0:
                            phid[j] = h * drive[s, j]
                        else:
                            phid[j] = np.expm1(x) / lam[s, j] * drive[s, j]
                    last_h = h
                i = current_a[k]
                for j in range(n_modes):
                    z[j] = decay[j] * z[j] + phid[j] * i
            for j in range(n_modes):
                z_end[s, j] = z[j]

    _KERNEL_CACHE["kernel"] = kernel
    return kernel


def numba_available() -> bool:
    """True when the compiled kernel can be used."""
    return _numba_kernel() is not None


def boundary_surfaces(lam: np.ndarray, drive: np.ndarray, z0: np.ndarray, duration_s: np.ndarray,
                      current_a: np.ndarray, weights: np.ndarray, *, stride: int = 64,
                      backend: str = "auto") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Surface values at every step boundary, exactly (zero-order hold).

    Parameters
    ----------
    lam, drive : numpy.ndarray
        Eigenvalues (1/s) and modal input vectors (1/(A s)) of each set, shape (n_sets, n_modes).
    z0 : numpy.ndarray
        Initial modal states, shape (n_sets, n_modes).
    duration_s, current_a : numpy.ndarray
        Step lengths (s) and cell currents (A), shape (n_steps,).
    weights : numpy.ndarray
        Surface weights, shape (2, n_modes).
    stride : int
        Modal states are kept every ``stride`` steps (to restart inside the run).
    backend : str
        ``"numba"``, ``"numpy"`` or ``"auto"`` (Numba when installed).

    Returns
    -------
    surfaces : numpy.ndarray
        (n_sets, n_steps + 1, 2): negative and positive surface values at ``t_0 .. t_K``.
    checkpoints : numpy.ndarray
        (n_sets, n_steps // stride + 1, n_modes): modal states at steps ``0, stride, ...``.
    z_end : numpy.ndarray
        (n_sets, n_modes): modal state at the end.
    """
    duration_s = np.ascontiguousarray(duration_s, dtype=float)
    current_a = np.ascontiguousarray(current_a, dtype=float)
    n_sets, n_modes = z0.shape
    kernel = None if backend == "numpy" else _numba_kernel()
    if backend == "numba" and kernel is None:
        raise SimulationError("the numba backend was asked for but numba is not installed")
    if kernel is None:
        return _boundary_states_numpy(lam, drive, z0, duration_s, current_a, weights, stride)
    n_steps = duration_s.size
    surfaces = np.empty((n_sets, n_steps + 1, 2))
    checkpoints = np.empty((n_sets, n_steps // stride + 1, n_modes))
    z_end = np.empty((n_sets, n_modes))
    kernel(np.ascontiguousarray(lam), np.ascontiguousarray(drive), np.ascontiguousarray(z0), duration_s, current_a,
           np.ascontiguousarray(weights), int(stride), surfaces, checkpoints, z_end)
    return surfaces, checkpoints, z_end


def states_at(lam: np.ndarray, drive: np.ndarray, checkpoints: np.ndarray, duration_s: np.ndarray,
              current_a: np.ndarray, step: np.ndarray, stride: int) -> np.ndarray:
    """Modal states at the start of ``step`` (one index per set), restarted from the checkpoints."""
    sets = np.arange(checkpoints.shape[0])
    z = checkpoints[sets, step // stride].copy()
    first = (step // stride) * stride
    for k in range(int((step - first).max(initial=0))):
        k_step = first + k
        active = k_step < step
        decay, phi = step_coefficients(lam, duration_s[np.minimum(k_step, duration_s.size - 1)][:, None])
        advanced = decay * z + phi * drive * current_a[np.minimum(k_step, current_a.size - 1)][:, None]
        z = np.where(active[:, None], advanced, z)
    return z
