"""Simulation layer: MuJoCo scene composition, robot, cameras, scene pieces, stepping."""

from rmbench.sim.gl import select_backend

# MuJoCo fixes its OpenGL backend when first imported: choose it before anything imports mujoco.
select_backend()
