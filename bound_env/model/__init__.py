"""The paper's planar model: its parameters, equations of motion, guards and resets, the
reference and compiled integrators, the apex-to-apex stride and its exact Jacobian, the
numerics on any map, terrain and model error."""
