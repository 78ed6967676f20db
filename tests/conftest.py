"""Test session set-up."""

import os
import resource

import pytest

# MuJoCo picks its OpenGL backend when first imported, whichever test module does that first;
# there is no display here, so offscreen rendering (the emulated camera) needs EGL.
os.environ.setdefault("MUJOCO_GL", "egl")

from hypothesis import HealthCheck, settings  # noqa: E402

# Property-based tests draw the same examples on every run (derandomize) and a bounded number of
# them, so that `make test` and CI are repeatable; HYPOTHESIS_PROFILE=dev explores afresh.
settings.register_profile("ci", derandomize=True, max_examples=150, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
settings.register_profile("dev", max_examples=2000, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


@pytest.fixture
def high_descriptors():
    """Descriptors held open so that the next ones this process opens are numbered past 1,024
    (select()'s limit), the open-files limit raised for it where needed and put back after."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if hard != resource.RLIM_INFINITY and hard < 1200:
        pytest.skip(f"this machine allows {hard} open files a process, under the 1,200 needed")
    if soft != resource.RLIM_INFINITY and soft < 1200:
        resource.setrlimit(resource.RLIMIT_NOFILE, (2048 if hard == resource.RLIM_INFINITY else min(2048, hard), hard))
    held = [os.open(os.devnull, os.O_RDONLY) for _ in range(1100)]
    try:
        yield
    finally:
        for fd in held:
            os.close(fd)
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))
