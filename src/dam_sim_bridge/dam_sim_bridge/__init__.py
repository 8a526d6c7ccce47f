"""PyBullet stand-in for the three-fingered DAM hand, speaking the device link (UDP) or
emulating a Dynamixel bus. The experiments that run on it are in ``dam_experiments``.
"""

import os as _os

# Small matrix products make OpenBLAS start worker threads that busy-wait afterwards; on a
# machine with few cores they take CPU from DDS and the real-time loops. One thread is faster
# for the tiny arrays used here. A value set by the user wins.
for _var in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    _os.environ.setdefault(_var, '1')
