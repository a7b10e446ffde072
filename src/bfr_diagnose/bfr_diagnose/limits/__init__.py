"""Detection limits of ``bfr diagnose`` (``bfr limits``): a randomized blind test.

- :mod:`.cases`: the seeded draw of one case (truth generator, effects and sizes, sensors,
  orbit speed, camera, controller gains), reproducible from ``(seed, index)`` alone;
- :mod:`.generate`: the recording of a case (rigid closed loop, force-based contact model),
  written as a rig log or a bag and read back through the readers;
- :mod:`.peer`: the PySINDy peer (sparse regression of the model residual on a fixed library
  of physical terms, threshold by held-out error, fixed term-to-mechanism mapping);
- :mod:`.runner`: one case end to end (both tools, scored alike) and the Dask run
  (LocalCluster or ``--scheduler``), resumable, one record per case on disk;
- :mod:`.stats`: detection curves (logistic in log size), 50 % and 90 % sizes with
  bootstrap intervals, parameter error, confusion matrix, pairs and triples, Wilson
  intervals; :mod:`.plots`: the PNG figures; :mod:`.cli`: ``bfr limits``.
"""
