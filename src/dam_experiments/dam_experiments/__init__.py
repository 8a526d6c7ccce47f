"""Simulated DAM experiments on the PyBullet stand-in: single trials, Fig. 7 sweeps over
displacement, stiffness, friction angle and object (local or on a Dask cluster), their
tables, reports and plots.
"""

import os as _os

# Small matrix products make OpenBLAS start worker threads that busy-wait afterwards; on a
# machine with few cores they take CPU from the trials running beside them. One thread is
# faster for the tiny arrays used here. A value set by the user wins.
for _var in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    _os.environ.setdefault(_var, '1')
