import os

# Keep the suite's torch and BLAS work on one thread each: the machine has 2 cores.
os.environ.setdefault("OMP_NUM_THREADS", "1")
