"""JAX's CPU settings: flags that must be set before JAX's first computation.

:func:`configure_xla_cpu` is called by the command line before anything
else, and by :func:`bayeshopf.ensure_x64` the first time it runs, that is,
before the first computation of any of bayeshopf's functions; a user calls
neither.
"""

from __future__ import annotations

import os

from threadpoolctl import threadpool_limits

__all__ = ["configure_xla_cpu"]


#: XLA flag that keeps the CPU backend's Eigen work on one thread per computation.
SINGLE_THREAD_EIGEN = "--xla_cpu_multi_thread_eigen=false"
#: XLA flag that compiles CPU fusions with the classic emitters (jaxlib ≥ 0.10).
CLASSIC_FUSION = "--xla_cpu_use_fusion_emitters=false"
#: XLA flag that makes the CPU appear as several devices.
HOST_DEVICES = "--xla_force_host_platform_device_count"
#: Threads of OpenBLAS, in whose scipy build XLA's CPU LAPACK kernels run.
BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "1")


def _jaxlib_version() -> tuple[int, ...]:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return tuple(int(p) for p in version("jaxlib").split(".")[:2])
    except (PackageNotFoundError, ValueError):
        return (0,)


def configure_xla_cpu(host_devices: int = 1) -> list[str]:
    """Add the CPU flags below to ``XLA_FLAGS``, each unless the user set it.

    - :data:`SINGLE_THREAD_EIGEN`. With XLA's multithreaded Eigen pool, jaxlib
      0.10 on CPU now and then stalls compiling the NUTS programs, every thread
      idle in ``CompileAndLoad`` (PyAutoFit's issue #1528 describes the same stall
      and the same cure). The models here are small, so one thread per
      computation costs nothing measurable.
    - :data:`CLASSIC_FUSION` (jaxlib ≥ 0.10 only: older XLA aborts on flags it
      does not know). The fusion emitters cost compile time, not run time.

    - With ``host_devices > 1``, :data:`HOST_DEVICES` ``=host_devices``: the CPU
      appears as that many devices, and NUTS splits its chains between them
      (:func:`~bayeshopf.inference.devices.spread_devices`). The CLI asks for
      one per core it may use, up to four (the chains). With one thread per
      computation (above), one device computes on one core at a time.

    It also gives OpenBLAS one thread unless the user set ``OPENBLAS_NUM_THREADS``:
    it sets that variable to 1 (:data:`BLAS_THREADS`), which an OpenBLAS reads
    when it loads, and limits those already loaded to one thread with
    ``threadpoolctl``. There are two: NumPy's, loaded with NumPy (and so before
    any caller can run this), which computes the features' least squares and the
    bands' products, and SciPy's, loaded with its linear algebra, whose
    Cholesky factorisations and triangular solves jaxlib calls on CPU. Their
    worker threads busy-wait between calls, and the matrices here are far too
    small to gain from them: SciPy's slows the NUTS stage with two devices, and
    NumPy's takes the second core from the figure process while the CLI computes
    features (measurements in ``docs/changelog.md``).

    The XLA flags take effect only before JAX's first computation in the process
    (the CLI and the test suite call this first).

    Args:
        host_devices: CPU devices wanted (1: JAX's default, no flag added).

    Returns:
        The flags of this function now in ``XLA_FLAGS``.
    """
    if BLAS_THREADS[0] not in os.environ:
        os.environ[BLAS_THREADS[0]] = BLAS_THREADS[1]      # those that load from now on
        threadpool_limits(int(BLAS_THREADS[1]), user_api="blas")   # those loaded already
    flags = os.environ.get("XLA_FLAGS", "")
    wanted = [SINGLE_THREAD_EIGEN]
    if _jaxlib_version() >= (0, 10):
        wanted.append(CLASSIC_FUSION)
    if host_devices > 1:
        wanted.append(f"{HOST_DEVICES}={int(host_devices)}")
    for flag in wanted:
        if flag.split("=")[0] not in flags:
            flags = f"{flags} {flag}".strip()
    os.environ["XLA_FLAGS"] = flags
    return [f for f in wanted if f in flags]
