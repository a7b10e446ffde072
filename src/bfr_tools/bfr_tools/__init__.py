"""The tools of bfr, at the top of the dependency order.

The ``bfr`` command line (:mod:`.cli`, subcommands registered by name), ``bfr run`` and
``bfr doctor``, the rig launcher (:mod:`.rig`, ``launch/rig.launch.py``), the bench
(:mod:`.bench`), the controller's and the camera's evaluations (:mod:`.control_eval`,
:mod:`.camera_eval`) and the seed's perturbation study (:mod:`.analysis`).
"""
