"""Control side of bfr.

Controller law, closed-loop harness, controller node and the ``bfr`` command line of the bfr
Butterfly robot node suite.
"""
