"""treegen: Weber-Penn trees for game engines."""
import os

# One BLAS/LAPACK thread, set before numpy loads: a threaded reduction sums in another order,
# so the wind solve would write different bytes under `treegen make` (all cores) and a Dask
# worker (one thread, Dask's default); at these sizes (J <= 256) one thread is also faster.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

__version__ = "0.1.0"
