"""ROS 2 plumbing shared by the bfr nodes (simulator, camera, controller, recorder).

No physics and no vision: the QoS profiles of the topic contract, parameters mirrored from
the packages' YAML files (declared, read back, validated), time-stamp and image conversion,
and the standard node ``main`` with a clean SIGINT/SIGTERM shutdown
(:mod:`bfr_ros.node_common`).
"""
