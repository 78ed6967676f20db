"""Test session set-up."""

import os

# MuJoCo picks its OpenGL backend when first imported, whichever test module does that first;
# there is no display here, so offscreen rendering (the emulated camera) needs EGL.
os.environ.setdefault("MUJOCO_GL", "egl")
