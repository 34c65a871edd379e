"""How imutool's compiled (numba) kernels are built and run — not a file format.

- :mod:`formats.jit.cache`: the per-user, versioned folder where compiled kernels are cached (every module with a cached
  kernel imports it first), and the one-line "compiling … (first run only)" notice.
- :mod:`formats.jit.warm`: a cold first run compiles on two cores, a second process taking the other half.
- :mod:`formats.jit.typing_memo`: numba's call typing asked once per distinct question (~25 % less compile CPU).
- :mod:`formats.jit.threads`: how many threads one job may use (CSV, pyarrow, numba and BLAS pools).
- :mod:`formats.jit.blas_probe`: numba's start-up without importing scipy.linalg (its BLAS probe answered by
  finding the module; 0.15 s of every command's start).

It lives under ``formats`` because imports only go downward (``imutool`` → ``calibration`` → ``formats``) and the
file readers' kernels need it too.
"""
