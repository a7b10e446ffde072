"""The orbital stabilisation controller of bfr.

Virtual constraint, periodic orbit, transverse linearisation, periodic Riccati gains,
estimator and supervisor (pure numpy, :mod:`bfr_control.controller`), and the thin controller
node (:mod:`bfr_control.controller_node`).
"""
