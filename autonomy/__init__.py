"""Robot-side stack of depthnav: what would run on the real robot.

Pure numpy + numba. Never imports ``mujoco``, ``sim`` or ``rerun``: inputs and outputs
are arrays and frozen dataclasses (depth images in metres, odometry increments, a
:class:`autonomy.maps.vectormap.VectorMap`).
"""
