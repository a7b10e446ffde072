"""Camera side of bfr.

Camera model, calibration, ball detector and camera node of the bfr Butterfly robot node
suite (pure-numpy core, thin node module).
"""
