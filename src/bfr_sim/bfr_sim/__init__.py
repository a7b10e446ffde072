"""Simulator side of bfr.

Physics model, integrators, renderer, recordings I/O, diagnosis core, simulator and recorder
nodes of the bfr Butterfly robot node suite (pure-numpy core, thin node modules).
"""
