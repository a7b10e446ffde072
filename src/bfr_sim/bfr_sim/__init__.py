"""The emulated rig of bfr.

The renderer of the camera's frames (:mod:`bfr_sim.render`), the closed-loop harness that
runs the model, the sensor models and the real controller offline
(:mod:`bfr_sim.closed_loop`, ``bfr simulate``), and the simulator and recorder nodes.
"""
