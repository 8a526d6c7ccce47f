"""The joint samples of one grasp, recorded by the sequence for the object's pose
(:mod:`dam_spcm_controller.pose_tracking`). Pure numpy; no rclpy."""

from __future__ import annotations

import numpy as np

from dam_spcm_controller.errors import InputError

__all__ = ['JointHistory']


class JointHistory:
    """Joint samples of one grasp: times [s], angles [rad], torques [N*m].

    Appending is cheap (a row copy into a buffer that doubles when full); nothing is checked
    (the caller, :class:`~dam_spcm_controller.sequence.DamSequence`, has checked the arrays).

    Parameters
    ----------
    n_joints
        Joints per sample (3 per finger).
    capacity
        Initial number of rows.
    """

    def __init__(self, n_joints: int, capacity: int = 4096) -> None:
        if int(n_joints) < 1 or int(capacity) < 1:
            raise InputError(f'n_joints and capacity must be positive, got {n_joints!r}, '
                             f'{capacity!r}')
        self._n = int(n_joints)
        self._t = np.empty(int(capacity))
        self._q = np.empty((int(capacity), self._n))
        self._tau = np.empty((int(capacity), self._n))
        self._len = 0

    def append(self, t: float, positions: np.ndarray, efforts: np.ndarray) -> None:
        """Add one sample: time [s], (n,) angles [rad], (n,) torques [N*m]."""
        k = self._len
        if k == self._t.shape[0]:
            self._t = np.concatenate([self._t, np.empty(k)])
            self._q = np.concatenate([self._q, np.empty((k, self._n))])
            self._tau = np.concatenate([self._tau, np.empty((k, self._n))])
        self._t[k] = t
        self._q[k] = positions
        self._tau[k] = efforts
        self._len = k + 1

    def clear(self) -> None:
        """Forget every sample (the buffers are kept)."""
        self._len = 0

    def __len__(self) -> int:
        return self._len

    @property
    def n_joints(self) -> int:
        return self._n

    @property
    def times(self) -> np.ndarray:
        """(k,) sample times [s] (a read-only view)."""
        view = self._t[:self._len]
        view.setflags(write=False)
        return view

    @property
    def positions(self) -> np.ndarray:
        """(k, n) joint angles [rad] (a read-only view)."""
        view = self._q[:self._len]
        view.setflags(write=False)
        return view

    @property
    def efforts(self) -> np.ndarray:
        """(k, n) joint torques [N*m] (a read-only view)."""
        view = self._tau[:self._len]
        view.setflags(write=False)
        return view

    @classmethod
    def from_arrays(cls, times: np.ndarray, positions: np.ndarray,
                    efforts: np.ndarray) -> JointHistory:
        """A history of recorded arrays: (k,) times [s], (k, n) angles [rad] and torques
        [N*m].

        Raises
        ------
        InputError
            Shapes that do not match, NaN/inf, or times that decrease.
        """
        t = np.asarray(times, dtype=np.float64)
        q = np.asarray(positions, dtype=np.float64)
        tau = np.asarray(efforts, dtype=np.float64)
        if t.ndim != 1 or q.ndim != 2 or q.shape != tau.shape or q.shape[0] != t.shape[0]:
            raise InputError(f'times (k,), positions and efforts (k, n) must match, got '
                             f'{t.shape}, {q.shape}, {tau.shape}')
        for name, arr in (('times', t), ('positions', q), ('efforts', tau)):
            if not np.isfinite(arr).all():
                raise InputError(f'{name} must be finite')
        if t.shape[0] > 1 and (np.diff(t) < 0.0).any():
            raise InputError('times must not decrease')
        history = cls(q.shape[1], max(1, t.shape[0]))
        for k in range(t.shape[0]):
            history.append(float(t[k]), q[k], tau[k])
        return history
