"""Test session set-up."""

import os

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
