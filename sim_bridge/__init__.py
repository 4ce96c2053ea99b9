"""Contextual MuJoCo tasks whose physics changes under the agent (pure Python, no ROS)."""

from __future__ import annotations

import os

# mujoco picks its OpenGL backend once, at import. Headless machines (CI, robots, containers)
# have no display for the default GLFW backend, so default to EGL there; an explicit MUJOCO_GL
# (e.g. osmesa when EGL is unavailable) always wins.
if 'MUJOCO_GL' not in os.environ and not os.environ.get('DISPLAY'):
    os.environ['MUJOCO_GL'] = 'egl'
